// Calibration files, the refusal checks, and rectification maps checked against a constructed rig: raw
// cameras with distortion and a rotated right eye, 3D points projected through them by hand.
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/geometry/calibrate.hpp"
#include "core/geometry/rectify.hpp"
#include "drivers/calibration_file.hpp"

using namespace stereod;
using geometry::PairCalibration;

namespace {

/// A 640x480 pair: 12 cm baseline, the right eye turned 1 degree about y and 0.5 about x, mild distortion.
PairCalibration constructed_pair()
{
	PairCalibration c;
	c.image_size = {640, 480};
	c.k_left = {520, 0, 322, 0, 521, 238, 0, 0, 1};
	c.k_right = {525, 0, 316, 0, 524, 244, 0, 0, 1};
	c.distortion_left = {-0.12, 0.05, 0.0005, -0.0003, 0};
	c.distortion_right = {-0.10, 0.04, -0.0004, 0.0002, 0};
	c.r = geometry::rotation_from_vector({0.5 * CV_PI / 180, 1.0 * CV_PI / 180, 0.1 * CV_PI / 180});
	c.t = {-0.12, 0.002, 0.001};
	return c;
}

cv::Point2d project(const cv::Matx33d &k, const std::vector<double> &d, const cv::Vec3d &p)
{
	std::vector<cv::Point2d> out;
	cv::projectPoints(std::vector<cv::Point3d>{cv::Point3d(p)}, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), k, d, out);
	return out[0];
}

/// The raw pixel a remap table sends rectified pixel (u, v) to (bilinear over the fixed-point tables).
cv::Point2d map_lookup(const cv::Mat &map, const cv::Mat &fraction, cv::Point2d rectified)
{
	cv::Mat xy;
	cv::convertMaps(map, fraction, xy, cv::noArray(), CV_32FC2);
	cv::Mat out;
	cv::Mat mx(1, 1, CV_32F, cv::Scalar(static_cast<float>(rectified.x)));
	cv::Mat my(1, 1, CV_32F, cv::Scalar(static_cast<float>(rectified.y)));
	std::vector<cv::Mat> channels;
	cv::split(xy, channels);
	cv::Mat sx, sy;
	cv::remap(channels[0], sx, mx, my, cv::INTER_LINEAR);
	cv::remap(channels[1], sy, mx, my, cv::INTER_LINEAR);
	return {sx.at<float>(0, 0), sy.at<float>(0, 0)};
}

std::string temp_path(const std::string &name)
{
	return (std::filesystem::temp_directory_path() / ("stereod_test_" + name)).string();
}

} // namespace

TEST(Rectification, MapsPutAPointOnOneRowAndItsDepthFromTheRectifiedRig)
{
	const PairCalibration c = constructed_pair();
	ASSERT_TRUE(geometry::calibration_problems(c, c.image_size).empty());
	const geometry::Rectification rect = geometry::make_rectification(c, c.image_size);
	EXPECT_NEAR(rect.rig.baseline_m, cv::norm(c.t), 1e-9); // rectification keeps the baseline's length
	// stereoRectify's rotations, recomputed here, take each raw camera to the common rectified one.
	cv::Mat r1, r2, p1, p2, q;
	cv::stereoRectify(c.k_left, c.distortion_left, c.k_right, c.distortion_right, c.image_size, c.r, c.t, r1, r2,
			  p1, p2, q, cv::CALIB_ZERO_DISPARITY, 0, c.image_size);
	const cv::Matx33d r_left(r1);
	for (const cv::Vec3d &x_left :
	     {cv::Vec3d(0.3, -0.2, 2.5), cv::Vec3d(-0.8, 0.4, 6.0), cv::Vec3d(0.05, 0.1, 1.2)}) {
		const cv::Vec3d x_right = c.r * x_left + c.t;
		// The point in the rectified left frame; its rectified pixels in both eyes by the rig.
		const cv::Vec3d x_rect = r_left * x_left;
		const auto left_px = rect.rig.project(x_rect);
		ASSERT_TRUE(left_px);
		const cv::Point2d right_px(left_px->x - rect.rig.fx * rect.rig.baseline_m / x_rect[2], left_px->y);
		// The maps must send those rectified pixels to where the raw cameras saw the point.
		const cv::Point2d raw_left = project(c.k_left, c.distortion_left, x_left);
		const cv::Point2d raw_right = project(c.k_right, c.distortion_right, x_right);
		const cv::Point2d looked_left = map_lookup(rect.left_map, rect.left_map_fraction, *left_px);
		const cv::Point2d looked_right = map_lookup(rect.right_map, rect.right_map_fraction, right_px);
		EXPECT_LT(cv::norm(looked_left - raw_left), 0.05) << looked_left << " vs " << raw_left;
		EXPECT_LT(cv::norm(looked_right - raw_right), 0.05) << looked_right << " vs " << raw_right;
		// And the rig's depth from that disparity is the rectified point's depth.
		const auto back = rect.rig.triangulate(left_px->x, left_px->y, left_px->x - right_px.x);
		ASSERT_TRUE(back);
		EXPECT_NEAR((*back)[2], x_rect[2], 1e-9);
	}
}

TEST(Rectification, RectifiedImagesKeepTheirSizeAndType)
{
	const PairCalibration c = constructed_pair();
	const geometry::Rectification rect = geometry::make_rectification(c, c.image_size);
	StereoFrame frame;
	frame.sequence = 7;
	frame.left = cv::Mat(480, 640, CV_8UC3, cv::Scalar(10, 20, 30));
	frame.right = cv::Mat(480, 640, CV_8UC3, cv::Scalar(40, 50, 60));
	const StereoFrame out = geometry::rectify_frame(rect, frame);
	EXPECT_EQ(out.sequence, 7u);
	EXPECT_EQ(out.left.size(), frame.left.size());
	EXPECT_EQ(out.right.type(), CV_8UC3);
	EXPECT_NE(out.left.data, frame.left.data); // the pool frame's pixels stay the camera's
	EXPECT_EQ(out.left.at<cv::Vec3b>(240, 320), cv::Vec3b(10, 20, 30));
}

TEST(CalibrationProblems, EachBadCalibrationIsNamed)
{
	const cv::Size image(640, 480);
	auto expect_problem = [&](PairCalibration c, const std::string &word) {
		const auto problems = geometry::calibration_problems(c, image);
		ASSERT_FALSE(problems.empty()) << "expected a problem about '" << word << "'";
		bool found = false;
		for (const auto &p : problems)
			found = found || p.find(word) != std::string::npos;
		EXPECT_TRUE(found) << problems.front();
	};
	PairCalibration c = constructed_pair();
	c.image_size = {1280, 960};
	expect_problem(c, "1280x960");
	c = constructed_pair();
	c.k_left(0, 0) = std::numeric_limits<double>::quiet_NaN();
	expect_problem(c, "M1 has a value that is not a finite number");
	c = constructed_pair();
	c.t[0] = 0.12; // eyes swapped
	expect_problem(c, "swapped");
	c = constructed_pair();
	c.t = {0.001, -0.12, 0}; // one above the other
	expect_problem(c, "side-by-side");
	c = constructed_pair();
	c.r(0, 0) = 2;
	expect_problem(c, "not a rotation");
	c = constructed_pair();
	c.k_right(0, 2) = 900;
	expect_problem(c, "outside");
	c = constructed_pair();
	c.distortion_left = {0.1, 0.2, 0.3};
	expect_problem(c, "3 coefficients");
	c = constructed_pair();
	c.t = {0, 0, 0};
	expect_problem(c, "same place");
}

TEST(CalibrationFile, WrittenThenReadGivesTheSameRig)
{
	const PairCalibration c = constructed_pair();
	for (const char *ext : {".yml", ".xml", ".json"}) {
		const std::string path = temp_path(std::string("calibration") + ext);
		drivers::write_calibration(path, c, c.image_size, {0.3, 0.25, 0.28, 13, 0.025});
		const PairCalibration back = drivers::read_calibration(path);
		EXPECT_EQ(back.image_size, c.image_size) << ext;
		EXPECT_LT(cv::norm(back.k_left - c.k_left), 1e-9) << ext;
		EXPECT_LT(cv::norm(back.t - c.t), 1e-12) << ext;
		ASSERT_TRUE(back.rectifying.has_value()) << ext;
		EXPECT_TRUE(geometry::calibration_problems(back, c.image_size).empty()) << ext;
		// The file's own rectification and the one computed from M, D, R, T agree.
		const auto from_file = geometry::make_rectification(back, c.image_size).rig;
		const auto computed = geometry::make_rectification(c, c.image_size).rig;
		EXPECT_NEAR(from_file.fx, computed.fx, 1e-9) << ext;
		EXPECT_NEAR(from_file.baseline_m, computed.baseline_m, 1e-12) << ext;
		std::remove(path.c_str());
	}
}

TEST(CalibrationFile, MissingKeysAndBadFilesNameThePathAndKey)
{
	const std::string path = temp_path("partial.yml");
	{
		cv::FileStorage file(path, cv::FileStorage::WRITE);
		file << "M1" << cv::Mat(cv::Matx33d::eye()) << "M2" << cv::Mat(cv::Matx33d::eye());
	}
	try {
		drivers::read_calibration(path);
		FAIL() << "a calibration without R and T was read";
	} catch (const drivers::CalibrationError &e) {
		EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
		EXPECT_NE(std::string(e.what()).find("'R'"), std::string::npos) << e.what();
	}
	{
		std::ofstream garbage(path);
		garbage << "this: [is not: {an opencv file\n";
	}
	EXPECT_THROW(drivers::read_calibration(path), drivers::CalibrationError);
	std::remove(path.c_str());
	EXPECT_THROW(drivers::read_calibration(path), drivers::CalibrationError);
}

TEST(Calibrate, RecoversAConstructedRigFromSyntheticBoardViews)
{
	// Board corners projected through the constructed pair from 12 poses: the fit must find T and the
	// focal lengths again, with an RMS near zero (the corners are exact).
	const PairCalibration truth = constructed_pair();
	const geometry::Chessboard board{{9, 6}, 0.03};
	std::vector<std::vector<cv::Point2f>> left, right;
	for (int i = 0; i < 12; ++i) {
		const cv::Vec3d rvec(0.3 * std::sin(i * 1.3), 0.35 * std::cos(i * 0.7), 0.1 * std::sin(i * 2.1));
		const cv::Vec3d tvec(-0.12 + 0.02 * std::sin(i * 0.9), -0.08 + 0.02 * std::cos(i * 1.7),
				     0.55 + 0.05 * (i % 4));
		const cv::Matx33d r_board = geometry::rotation_from_vector(rvec);
		std::vector<cv::Point2f> l, r;
		for (int y = 0; y < 6; ++y)
			for (int x = 0; x < 9; ++x) {
				const cv::Vec3d corner(x * board.square_m, y * board.square_m, 0);
				const cv::Vec3d x_left = r_board * corner + tvec;
				l.push_back(cv::Point2f(project(truth.k_left, truth.distortion_left, x_left)));
				r.push_back(cv::Point2f(
					project(truth.k_right, truth.distortion_right, truth.r * x_left + truth.t)));
			}
		left.push_back(l);
		right.push_back(r);
	}
	const auto result = geometry::calibrate_pair(left, right, board, truth.image_size);
	EXPECT_LT(result.rms_px, 0.01);
	EXPECT_LT(cv::norm(result.calibration.t - truth.t), 1e-3) << result.calibration.t;
	EXPECT_NEAR(result.calibration.k_left(0, 0), truth.k_left(0, 0), 1.0);
	EXPECT_NEAR(result.calibration.k_right(1, 1), truth.k_right(1, 1), 1.0);
	EXPECT_THROW(geometry::calibrate_pair({left[0]}, {right[0]}, board, truth.image_size), std::invalid_argument);
}
