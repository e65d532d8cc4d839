#pragma once
// Readers of public dataset layouts and plain folders/videos. Each builds a list of timestamped image
// files (the index) without decoding anything, so its parsing can be tested on small fixtures.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "drivers/source.hpp"

namespace stereod::drivers::datasets {

struct Entry {
	int64_t device_ns = 0;
	int64_t lr_skew_ns = 0;
	std::string left;  ///< image file
	std::string right; ///< empty for monocular layouts
	std::string depth; ///< 16-bit PNG, TUM convention (5000 per metre); empty if none
};

struct Index {
	std::vector<Entry> entries;
	std::optional<StereoCalibration> calibration;
	double depth_scale = 5000.0;	///< raw depth units per metre
	std::vector<std::string> notes; ///< what the reader noticed (skipped lines, unmatched frames)
};

/// KITTI raw drive folder: image_02/ and image_03/ with data/*.png and timestamps.txt; the rectified
/// calibration from calib_cam_to_cam.txt in the drive folder or its parent (the date folder), if present.
Index kitti(const std::string &drive_dir);
/// P_rect_02 and P_rect_03 of a KITTI calib_cam_to_cam.txt -> intrinsics and baseline. Throws on bad input.
StereoCalibration parse_kitti_calibration(const std::string &file);
/// EuRoC / ASL: mav0/cam0 and mav0/cam1, each data.csv + data/*.png, paired by timestamp.
Index euroc(const std::string &sequence_dir);
/// TUM RGB-D: rgb.txt and depth.txt, associated by nearest timestamp within max_difference_s; intrinsics from
/// the sequence folder's name (tum_intrinsics), so a TUM sequence gets metric points and poses.
Index tum(const std::string &sequence_dir, double max_difference_s = 0.02);
/// The intrinsics TUM publishes for the camera a sequence name (rgbd_dataset_freiburgN_...) names: Freiburg 3's
/// own; ROS's default for Freiburg 1 and 2 (as TUM recommends for registered depth) and for other names (with
/// a note).
StereoCalibration tum_intrinsics(const std::string &sequence_name, std::vector<std::string> &notes);
/// A folder with left/ and right/ subfolders of images paired by sorted name; timestamps from
/// timestamps.txt (one per line, seconds) if present, else frame index / fps.
Index folder_pair(const std::string &dir, double fps);

/// "2011-09-26 13:02:25.964389445" -> nanoseconds since the Unix epoch (UTC).
int64_t parse_kitti_timestamp(const std::string &text);

} // namespace stereod::drivers::datasets
