#pragma once
// From a raw stereo calibration (what cv::stereoCalibrate measures) to the rectified rig every 3D stage
// assumes: both eyes undistorted and rotated so that a point lands on the same row in both, sharing one
// pinhole camera, the right eye `baseline_m` along +x.
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/frame.hpp"
#include "core/geometry/rig.hpp"

namespace stereod::geometry {

/// Two cameras as calibrated, before rectification. The right camera's pose in the left's frame follows
/// OpenCV: x_right = r x_left + t, so a right eye to the right of the left one has t[0] < 0.
struct PairCalibration {
	cv::Size image_size; ///< the images it was made from (0x0: not stated)
	cv::Matx33d k_left = cv::Matx33d::eye(), k_right = cv::Matx33d::eye();
	std::vector<double> distortion_left, distortion_right; ///< OpenCV's order (k1 k2 p1 p2 [k3 ...]); may be empty
	cv::Matx33d r = cv::Matx33d::eye();
	cv::Vec3d t{0, 0, 0};
	/// Rectification already computed with it (cv::stereoRectify's R1 R2 P1 P2), used as given when present.
	struct Rectifying {
		cv::Matx33d r_left, r_right;
		cv::Matx34d p_left, p_right;
	};
	std::optional<Rectifying> rectifying;
};

/// Why this calibration cannot serve images of `image` size (empty when it can): a different size, a
/// non-finite or impossible number, a zero baseline, the eyes swapped, a vertical rig, a rectification that
/// does not agree with the pose. Each entry is one sentence for the user.
std::vector<std::string> calibration_problems(const PairCalibration &calibration, cv::Size image);

/// The calibration's own rectification, or the one cv::stereoRectify computes for `image` (alpha 0, zero
/// disparity at infinity): what make_rectification builds its maps from and a calibration file records.
PairCalibration::Rectifying rectifying_for(const PairCalibration &calibration, cv::Size image);

/// Remap tables for both eyes and the rectified rig they produce.
struct Rectification {
	cv::Size size;
	cv::Mat left_map, left_map_fraction, right_map, right_map_fraction; ///< cv::remap's fixed-point form
	StereoRig rig;
};

/// Builds the maps once for images of `image` size (cv::stereoRectify with alpha 0 and zero disparity at
/// infinity when the calibration does not bring its own, then cv::initUndistortRectifyMap). Call only on a
/// calibration without problems for that size.
Rectification make_rectification(const PairCalibration &calibration, cv::Size image);

/// The rectified image of one eye (bilinear), into `out` (reallocated only when its size or type differ).
void rectify_left(const Rectification &rectification, const cv::Mat &in, cv::Mat &out);
void rectify_right(const Rectification &rectification, const cv::Mat &in, cv::Mat &out);

/// `in` with both eyes rectified into new images; everything else (times, status, depth, truth) shared.
StereoFrame rectify_frame(const Rectification &rectification, const StereoFrame &in);

} // namespace stereod::geometry
