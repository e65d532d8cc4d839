#pragma once
// Stereo calibration files: OpenCV's YAML/XML/JSON (cv::FileStorage) as OpenCV's stereo_calib sample and
// `stereoctl calibrate` write them.
//
//   M1, D1, M2, D2   each camera's matrix and distortion          (required: M1, M2)
//   R, T             the right camera's pose in the left's frame  (required)
//   R1, R2, P1, P2   a rectification made with them               (optional: computed when absent)
//   image_width, image_height                                     (optional: checked against the source)
#include <stdexcept>
#include <string>

#include "core/geometry/rectify.hpp"

namespace stereod::drivers {

class CalibrationError : public std::runtime_error
{
public:
	using std::runtime_error::runtime_error;
};

/// Reads `path`; throws CalibrationError("path: what is wrong") when it cannot be read or lacks a key.
geometry::PairCalibration read_calibration(const std::string &path);

/// What `stereoctl calibrate` measured beside the calibration, written as comments-with-values.
struct CalibrationReport {
	double rms_px = 0;	///< cv::stereoCalibrate's RMS re-projection error over both eyes
	double left_rms_px = 0; ///< each camera alone (cv::calibrateCamera)
	double right_rms_px = 0;
	int pairs = 0;		  ///< pairs used
	double square_size_m = 0; ///< the board's square: T is in these units
};

/// Writes the calibration and its rectification (R1 R2 P1 P2 Q) to `path` (format by extension: .yml/.yaml,
/// .xml, .json); throws CalibrationError when it cannot.
void write_calibration(const std::string &path, const geometry::PairCalibration &calibration, cv::Size image,
		       const CalibrationReport &report);

} // namespace stereod::drivers
