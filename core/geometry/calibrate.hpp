#pragma once
// Stereo calibration from chessboard pairs, as `stereoctl calibrate` runs it: corners found in both eyes,
// each camera calibrated alone for a start, then both together (cv::stereoCalibrate).
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rectify.hpp"

namespace stereod::geometry {

struct Chessboard {
	cv::Size inner_corners{9, 6}; ///< corners where four squares meet, across x down
	double square_m = 0.025;      ///< side of one square: the calibration's unit of length
};

/// The board's inner corners in one grey image, refined to sub-pixel; nothing unless all of them are seen.
std::optional<std::vector<cv::Point2f>> find_chessboard(const cv::Mat &grey, const Chessboard &board);

struct PairCalibrationResult {
	PairCalibration calibration;
	double rms_px = 0;	///< both eyes together, after cv::stereoCalibrate
	double left_rms_px = 0; ///< each camera alone
	double right_rms_px = 0;
	std::vector<double> pair_rms_px; ///< per pair, both eyes, with the final calibration
};

/// Calibrates a stereo pair from corners seen in both eyes of each pair (left[i] with right[i]); at least
/// three pairs (throws std::invalid_argument otherwise).
PairCalibrationResult calibrate_pair(const std::vector<std::vector<cv::Point2f>> &left,
				     const std::vector<std::vector<cv::Point2f>> &right, const Chessboard &board,
				     cv::Size image);

} // namespace stereod::geometry
