#include "core/geometry/rig.hpp"

#include <limits>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

namespace stereod::geometry {

std::optional<cv::Vec3d> StereoRig::triangulate(double u, double v, double disparity_px) const
{
	if (!(disparity_px > 0) || !std::isfinite(disparity_px) || !(fx > 0) || !(fy > 0))
		return std::nullopt;
	return back_project(u, v, depth(disparity_px));
}

std::optional<cv::Point2d> StereoRig::project(const cv::Vec3d &p) const
{
	if (!(p[2] > 1e-9))
		return std::nullopt;
	return cv::Point2d(fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy);
}

std::array<double, 16> Pose::matrix() const
{
	std::array<double, 16> m{};
	for (int row = 0; row < 3; ++row) {
		for (int col = 0; col < 3; ++col)
			m[static_cast<size_t>(row * 4 + col)] = r(row, col);
		m[static_cast<size_t>(row * 4 + 3)] = t[row];
	}
	m[15] = 1;
	return m;
}

Pose Pose::from_matrix(const std::array<double, 16> &m)
{
	Pose pose;
	for (int row = 0; row < 3; ++row) {
		for (int col = 0; col < 3; ++col)
			pose.r(row, col) = m[static_cast<size_t>(row * 4 + col)];
		pose.t[row] = m[static_cast<size_t>(row * 4 + 3)];
	}
	return pose;
}

double Pose::angle() const
{
	// The Rodrigues vector's length: exact near zero, where acos((trace - 1) / 2) loses half the digits.
	return cv::norm(vector_from_rotation(r));
}

cv::Matx33d rotation_from_vector(const cv::Vec3d &rvec)
{
	cv::Matx33d r;
	cv::Rodrigues(rvec, r);
	return r;
}

cv::Vec3d vector_from_rotation(const cv::Matx33d &r)
{
	cv::Vec3d v;
	cv::Rodrigues(r, v);
	return v;
}

cv::Matx33d fundamental_from_pose(const cv::Matx33d &k, const Pose &b_from_a)
{
	const cv::Vec3d &t = b_from_a.t;
	const cv::Matx33d tx(0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0);
	const cv::Matx33d k_inv = k.inv();
	return k_inv.t() * tx * b_from_a.r * k_inv;
}

cv::Matx33d rotation_from_quaternion(double qx, double qy, double qz, double qw)
{
	const double n = std::sqrt(qx * qx + qy * qy + qz * qz + qw * qw);
	if (!(n > 0))
		throw std::invalid_argument("zero quaternion");
	qx /= n, qy /= n, qz /= n, qw /= n;
	return {1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw),	  2 * (qx * qz + qy * qw),
		2 * (qx * qy + qz * qw),     1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw),
		2 * (qx * qz - qy * qw),     2 * (qy * qz + qx * qw),	  1 - 2 * (qx * qx + qy * qy)};
}

std::array<double, 4> quaternion_from_rotation(const cv::Matx33d &r)
{
	const double trace = r(0, 0) + r(1, 1) + r(2, 2);
	std::array<double, 4> q{};
	if (trace > 0) {
		const double s = 2 * std::sqrt(1 + trace);
		q = {(r(2, 1) - r(1, 2)) / s, (r(0, 2) - r(2, 0)) / s, (r(1, 0) - r(0, 1)) / s, s / 4};
	} else if (r(0, 0) > r(1, 1) && r(0, 0) > r(2, 2)) {
		const double s = 2 * std::sqrt(1 + r(0, 0) - r(1, 1) - r(2, 2));
		q = {s / 4, (r(0, 1) + r(1, 0)) / s, (r(0, 2) + r(2, 0)) / s, (r(2, 1) - r(1, 2)) / s};
	} else if (r(1, 1) > r(2, 2)) {
		const double s = 2 * std::sqrt(1 + r(1, 1) - r(0, 0) - r(2, 2));
		q = {(r(0, 1) + r(1, 0)) / s, s / 4, (r(1, 2) + r(2, 1)) / s, (r(0, 2) - r(2, 0)) / s};
	} else {
		const double s = 2 * std::sqrt(1 + r(2, 2) - r(0, 0) - r(1, 1));
		q = {(r(0, 2) + r(2, 0)) / s, (r(1, 2) + r(2, 1)) / s, s / 4, (r(1, 0) - r(0, 1)) / s};
	}
	return q;
}

double epipolar_distance(const cv::Matx33d &f, cv::Point2d x_a, cv::Point2d x_b)
{
	const cv::Vec3d line = f * cv::Vec3d(x_a.x, x_a.y, 1);
	const double norm = std::hypot(line[0], line[1]);
	if (!(norm > 1e-15))
		return std::numeric_limits<double>::infinity();
	return std::abs(line[0] * x_b.x + line[1] * x_b.y + line[2]) / norm;
}

} // namespace stereod::geometry
