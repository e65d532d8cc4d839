#include "core/geometry/calibrate.hpp"

#include <cmath>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod::geometry {
namespace {

std::vector<cv::Point3f> board_points(const Chessboard &board)
{
	std::vector<cv::Point3f> points;
	for (int y = 0; y < board.inner_corners.height; ++y)
		for (int x = 0; x < board.inner_corners.width; ++x)
			points.emplace_back(static_cast<float>(x * board.square_m),
					    static_cast<float>(y * board.square_m), 0.f);
	return points;
}

/// Sum of squared re-projection errors and the point count of one view.
std::pair<double, size_t> view_error(const std::vector<cv::Point3f> &object, const std::vector<cv::Point2f> &seen,
				     const cv::Matx33d &k, const std::vector<double> &distortion, const cv::Matx33d &r,
				     const cv::Vec3d &t)
{
	std::vector<cv::Point2f> projected;
	cv::projectPoints(object, cv::Mat(r), cv::Mat(t), k, distortion, projected);
	double sum = 0;
	for (size_t i = 0; i < seen.size(); ++i) {
		const cv::Point2f d = projected[i] - seen[i];
		sum += static_cast<double>(d.dot(d));
	}
	return {sum, seen.size()};
}

} // namespace

std::optional<std::vector<cv::Point2f>> find_chessboard(const cv::Mat &grey, const Chessboard &board)
{
	std::vector<cv::Point2f> corners;
	if (!cv::findChessboardCorners(grey, board.inner_corners, corners,
				       cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
		return std::nullopt;
	cv::cornerSubPix(grey, corners, cv::Size(11, 11), cv::Size(-1, -1),
			 cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01));
	return corners;
}

PairCalibrationResult calibrate_pair(const std::vector<std::vector<cv::Point2f>> &left,
				     const std::vector<std::vector<cv::Point2f>> &right, const Chessboard &board,
				     cv::Size image)
{
	if (left.size() != right.size() || left.size() < 3)
		throw std::invalid_argument(
			"stereo calibration needs at least three pairs with the board in both eyes");
	const std::vector<std::vector<cv::Point3f>> object(left.size(), board_points(board));
	PairCalibrationResult result;
	auto &c = result.calibration;
	c.image_size = image;
	// Each camera alone first: a good start for the joint fit, and its own error tells a bad eye apart.
	cv::Mat k_left, d_left, k_right, d_right, rvecs, tvecs;
	result.left_rms_px = cv::calibrateCamera(object, left, image, k_left, d_left, rvecs, tvecs);
	result.right_rms_px = cv::calibrateCamera(object, right, image, k_right, d_right, rvecs, tvecs);
	cv::Mat r, t, e, f;
	result.rms_px = cv::stereoCalibrate(
		object, left, right, k_left, d_left, k_right, d_right, image, r, t, e, f, cv::CALIB_USE_INTRINSIC_GUESS,
		cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-6));
	c.k_left = k_left;
	c.k_right = k_right;
	c.distortion_left = std::vector<double>(d_left.reshape(1, 1));
	c.distortion_right = std::vector<double>(d_right.reshape(1, 1));
	c.r = r;
	c.t = cv::Vec3d(t.reshape(1, 3));
	// Per pair, with the final numbers: the left board pose from the left eye alone, the right through R, T.
	for (size_t i = 0; i < left.size(); ++i) {
		cv::Mat rvec, tvec;
		cv::solvePnP(object[i], left[i], c.k_left, c.distortion_left, rvec, tvec);
		cv::Matx33d r_board;
		cv::Rodrigues(rvec, r_board);
		const cv::Vec3d t_board(tvec.reshape(1, 3));
		const auto [sum_l, n_l] = view_error(object[i], left[i], c.k_left, c.distortion_left, r_board, t_board);
		const auto [sum_r, n_r] = view_error(object[i], right[i], c.k_right, c.distortion_right, c.r * r_board,
						     c.r * t_board + c.t);
		result.pair_rms_px.push_back(std::sqrt((sum_l + sum_r) / static_cast<double>(n_l + n_r)));
	}
	return result;
}

} // namespace stereod::geometry
