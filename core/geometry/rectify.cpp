#include "core/geometry/rectify.hpp"

#include <cmath>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod::geometry {
namespace {

template <typename Matrix>
bool finite(const Matrix &m)
{
	for (int i = 0; i < Matrix::rows * Matrix::cols; ++i)
		if (!std::isfinite(m.val[i]))
			return false;
	return true;
}

bool finite(const std::vector<double> &values)
{
	for (const double v : values)
		if (!std::isfinite(v))
			return false;
	return true;
}

void check_camera(const char *name, const cv::Matx33d &k, cv::Size image, std::vector<std::string> &problems)
{
	if (k(0, 0) <= 0 || k(1, 1) <= 0 || std::abs(k(2, 2) - 1) > 1e-9 || k(2, 0) != 0 || k(2, 1) != 0) {
		problems.push_back(fmt::format("{} is not a camera matrix (fx {}, fy {}, last row {} {} {})", name,
					       k(0, 0), k(1, 1), k(2, 0), k(2, 1), k(2, 2)));
		return;
	}
	if (k(0, 2) < 0 || k(0, 2) > image.width || k(1, 2) < 0 || k(1, 2) > image.height)
		problems.push_back(fmt::format("{}'s principal point ({:.1f}, {:.1f}) lies outside the {}x{} image",
					       name, k(0, 2), k(1, 2), image.width, image.height));
}

cv::Mat distortion(const std::vector<double> &d)
{
	return d.empty() ? cv::Mat() : cv::Mat(d, true).reshape(1, 1);
}

} // namespace

std::vector<std::string> calibration_problems(const PairCalibration &c, cv::Size image)
{
	std::vector<std::string> problems;
	if (c.image_size.area() > 0 && c.image_size != image)
		problems.push_back(fmt::format("it was made for {}x{} images, the source delivers {}x{}",
					       c.image_size.width, c.image_size.height, image.width, image.height));
	const std::pair<const char *, bool> finiteness[] = {
		{"M1", finite(c.k_left)},
		{"M2", finite(c.k_right)},
		{"D1", finite(c.distortion_left)},
		{"D2", finite(c.distortion_right)},
		{"R", finite(c.r)},
		{"T", finite(c.t)},
		{"R1/R2/P1/P2", !c.rectifying || (finite(c.rectifying->r_left) && finite(c.rectifying->r_right) &&
						  finite(c.rectifying->p_left) && finite(c.rectifying->p_right))}};
	for (const auto &[name, ok] : finiteness)
		if (!ok)
			problems.push_back(fmt::format("{} has a value that is not a finite number", name));
	if (!problems.empty())
		return problems;
	check_camera("M1 (left camera)", c.k_left, image, problems);
	check_camera("M2 (right camera)", c.k_right, image, problems);
	for (const auto &[name, d] : {std::pair{"D1", &c.distortion_left}, std::pair{"D2", &c.distortion_right}})
		if (!d->empty() && d->size() != 4 && d->size() != 5 && d->size() != 8 && d->size() != 12 &&
		    d->size() != 14)
			problems.push_back(fmt::format("{} has {} coefficients (OpenCV takes 4, 5, 8, 12 or 14)", name,
						       d->size()));
	const cv::Matx33d should_be_identity = c.r.t() * c.r;
	if (cv::norm(should_be_identity - cv::Matx33d::eye()) > 1e-3 || cv::determinant(c.r) < 0)
		problems.push_back("R is not a rotation (R^T R is not the identity, or det R < 0)");
	const double baseline = cv::norm(c.t);
	if (baseline == 0) {
		problems.push_back("T is zero: the two cameras are at the same place");
	} else if (std::abs(c.t[1]) > std::abs(c.t[0]) || std::abs(c.t[2]) > std::abs(c.t[0])) {
		problems.push_back(
			fmt::format("T = ({:.4f}, {:.4f}, {:.4f}) is not a side-by-side rig (only horizontal "
				    "stereo is supported)",
				    c.t[0], c.t[1], c.t[2]));
	} else if (c.t[0] > 0) {
		problems.push_back(fmt::format("T[0] = {:.4f} > 0 puts the right camera to the left of the left one: "
					       "left and right swapped? (OpenCV's convention gives T[0] = -baseline)",
					       c.t[0]));
	}
	if (c.rectifying) {
		const auto &p1 = c.rectifying->p_left, &p2 = c.rectifying->p_right;
		if (p1(0, 0) <= 0 || p2(0, 0) <= 0) {
			problems.push_back("P1/P2 have no positive focal length");
		} else {
			const double rectified_baseline = -p2(0, 3) / p2(0, 0);
			if (std::abs(p2(1, 3)) > 1e-6 * std::abs(p2(0, 3)) + 1e-9)
				problems.push_back("P2 is vertically rectified (P2[1][3] != 0): only horizontal stereo "
						   "is supported");
			else if (rectified_baseline <= 0)
				problems.push_back(fmt::format(
					"P2[0][3] = {:.3f} gives a baseline <= 0: left and right swapped?", p2(0, 3)));
			else if (std::abs(rectified_baseline - baseline) > 0.02 * baseline)
				problems.push_back(
					fmt::format("P2 gives a baseline of {:.4f} m, T one of {:.4f} m: they are not "
						    "from the same calibration",
						    rectified_baseline, baseline));
			if (std::abs(p1(0, 2) - p2(0, 2)) > 1e-6)
				problems.push_back("P1 and P2 have different principal points (rectified without "
						   "CALIB_ZERO_DISPARITY): drop R1/R2/P1/P2 to have them recomputed");
		}
	}
	return problems;
}

PairCalibration::Rectifying rectifying_for(const PairCalibration &c, cv::Size image)
{
	if (c.rectifying)
		return *c.rectifying;
	cv::Mat r1, r2, p1, p2, q;
	cv::stereoRectify(c.k_left, distortion(c.distortion_left), c.k_right, distortion(c.distortion_right), image,
			  c.r, c.t, r1, r2, p1, p2, q, cv::CALIB_ZERO_DISPARITY, 0, image);
	return {cv::Matx33d(r1), cv::Matx33d(r2), cv::Matx34d(p1), cv::Matx34d(p2)};
}

Rectification make_rectification(const PairCalibration &c, cv::Size image)
{
	const auto [r_left, r_right, p_left, p_right] = rectifying_for(c, image);
	Rectification out;
	out.size = image;
	cv::initUndistortRectifyMap(c.k_left, distortion(c.distortion_left), r_left, p_left.get_minor<3, 3>(0, 0),
				    image, CV_16SC2, out.left_map, out.left_map_fraction);
	cv::initUndistortRectifyMap(c.k_right, distortion(c.distortion_right), r_right, p_right.get_minor<3, 3>(0, 0),
				    image, CV_16SC2, out.right_map, out.right_map_fraction);
	out.rig = StereoRig{p_left(0, 0), p_left(1, 1), p_left(0, 2), p_left(1, 2), -p_right(0, 3) / p_right(0, 0)};
	return out;
}

void rectify_left(const Rectification &rectification, const cv::Mat &in, cv::Mat &out)
{
	cv::remap(in, out, rectification.left_map, rectification.left_map_fraction, cv::INTER_LINEAR);
}

void rectify_right(const Rectification &rectification, const cv::Mat &in, cv::Mat &out)
{
	cv::remap(in, out, rectification.right_map, rectification.right_map_fraction, cv::INTER_LINEAR);
}

StereoFrame rectify_frame(const Rectification &rectification, const StereoFrame &in)
{
	StereoFrame out = in;
	out.left = cv::Mat();
	out.right = cv::Mat();
	rectify_left(rectification, in.left, out.left);
	if (!in.right.empty())
		rectify_right(rectification, in.right, out.right);
	return out;
}

} // namespace stereod::geometry
