#pragma once
// The rectified stereo rig and rigid-body poses: the geometry every 3D stage shares.
//
// Conventions (the protocol's): the left rectified camera's frame, x right, y down, z forward, metres.
// A pose T_a_b maps coordinates in frame b into frame a (p_a = T_a_b p_b), so T_world_curr is the current
// camera's pose in the world and chains as T_world_curr = T_world_prev * T_prev_curr.
#include <array>
#include <cmath>
#include <optional>

#include <opencv2/core.hpp>

namespace stereod::geometry {

/// Rectified pinhole stereo: both eyes share the intrinsics, the right eye sits baseline_m along +x.
struct StereoRig {
	double fx = 0, fy = 0, cx = 0, cy = 0; ///< left rectified camera, pixels
	double baseline_m = 0;		       ///< right camera's offset along the left camera's x axis

	[[nodiscard]] cv::Matx33d k() const { return {fx, 0, cx, 0, fy, cy, 0, 0, 1}; }
	/// Depth of a point seen at disparity d (pixels): z = f b / d.
	[[nodiscard]] double depth(double disparity_px) const { return fx * baseline_m / disparity_px; }
	/// The left-camera point seen at (u, v) at depth z.
	[[nodiscard]] cv::Vec3d back_project(double u, double v, double z) const
	{
		return {(u - cx) * z / fx, (v - cy) * z / fy, z};
	}
	/// The left-camera point seen at (u, v) with disparity d; nothing for d <= 0 or a non-finite one.
	[[nodiscard]] std::optional<cv::Vec3d> triangulate(double u, double v, double disparity_px) const;
	/// Where a left-camera point lands in the left image; nothing behind the camera.
	[[nodiscard]] std::optional<cv::Point2d> project(const cv::Vec3d &p) const;
	/// Standard deviation of a depth measured at disparity d with disparity noise sigma_d:
	/// dz = z^2 / (f b) * sigma_d (first order).
	[[nodiscard]] double depth_sigma(double z, double disparity_sigma_px) const
	{
		return z * z / (fx * baseline_m) * disparity_sigma_px;
	}
};

/// A rigid transform [R | t] (rotation, translation in metres).
struct Pose {
	cv::Matx33d r = cv::Matx33d::eye();
	cv::Vec3d t{0, 0, 0};

	[[nodiscard]] cv::Vec3d operator*(const cv::Vec3d &p) const { return r * p + t; }
	[[nodiscard]] Pose operator*(const Pose &other) const { return {r * other.r, r * other.t + t}; }
	[[nodiscard]] Pose inverse() const
	{
		const cv::Matx33d rt = r.t();
		return {rt, -(rt * t)};
	}
	/// Row-major 4x4, the protocol's form.
	[[nodiscard]] std::array<double, 16> matrix() const;
	static Pose from_matrix(const std::array<double, 16> &m);
	/// Rotation angle in radians.
	[[nodiscard]] double angle() const;
	[[nodiscard]] double distance() const { return std::sqrt(t.dot(t)); }
};

/// Rotation from a Rodrigues vector (axis * angle) and back.
cv::Matx33d rotation_from_vector(const cv::Vec3d &rvec);
cv::Vec3d vector_from_rotation(const cv::Matx33d &r);

/// Unit quaternions (qx, qy, qz, qw), the TUM format's order; the input need not be normalised (a zero one
/// throws std::invalid_argument). From a matrix by Shepperd's method (the largest diagonal term decides).
cv::Matx33d rotation_from_quaternion(double qx, double qy, double qz, double qw);
std::array<double, 4> quaternion_from_rotation(const cv::Matx33d &r);

/// The fundamental matrix of two views of the same camera K with relative pose [R|t] (x_b = R x_a + t):
/// F = K^-T [t]x R K^-1, so that x_b^T F x_a = 0 for a static point.
cv::Matx33d fundamental_from_pose(const cv::Matx33d &k, const Pose &b_from_a);

/// Seed 001 eq. 1: distance in pixels of x_b from the epipolar line F x_a; infinite for a degenerate line.
double epipolar_distance(const cv::Matx33d &f, cv::Point2d x_a, cv::Point2d x_b);

} // namespace stereod::geometry
