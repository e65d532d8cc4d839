#pragma once
// The synthetic stereo scene: textured planes (a back wall, the ground) seen by a pinhole stereo camera
// that may pan and sway, and textured person-sized movers standing on the ground. Everything is planar,
// so each surface is drawn exactly with one homography, and the truth (which pixel belongs to which mover,
// where each mover is and how fast it goes, the camera pose, depth) is known by construction.
#include <array>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/frame.hpp"
#include "drivers/source.hpp"

namespace stereod::drivers::sim {

struct Pose {
	cv::Matx33d r_cw; ///< camera-from-world rotation
	cv::Vec3d t_cw;	  ///< camera-from-world translation
};

/// A rectangle in the world with a photograph on it.
struct TexturedPlane {
	cv::Vec3d origin; ///< world position of texture pixel (0,0)
	cv::Vec3d axis_u; ///< world direction of texture +x, unit
	cv::Vec3d axis_v; ///< world direction of texture +y, unit
	double width_m = 0;
	double height_m = 0;
	cv::Mat texture;       ///< CV_8UC3
	uint8_t object_id = 0; ///< 0 for the static scene
};

/// A mover: a vertical textured board standing on the ground, moving at constant velocity between bounds.
struct Mover {
	uint8_t id = 0;
	double width_m = 0.6;
	double height_m = 1.7;
	cv::Vec3d start;	 ///< world position of the bottom centre at t = 0
	cv::Vec3d velocity;	 ///< m/s; reverses at the bounds
	cv::Vec2d x_bounds;	 ///< the mover turns around outside [lo, hi] in x ...
	cv::Vec2d z_bounds;	 ///< ... and in z
	double start_time_s = 0; ///< invisible before this
	/// Walks beside the camera instead: bottom centre = the camera's centre + pace_offset (on the ground),
	/// with the camera's velocity (seed 001 Fig. 4: a person keeping pace with a walking rig).
	bool paces_camera = false;
	cv::Vec3d pace_offset;
	cv::Mat texture;
	/// Bottom-centre position and velocity at time t (a triangle wave between the bounds).
	[[nodiscard]] std::pair<cv::Vec3d, cv::Vec3d> state_at(double t) const;
};

struct CameraIntrinsics {
	double fx = 0, fy = 0, cx = 0, cy = 0;
	[[nodiscard]] cv::Matx33d matrix() const { return {fx, 0, cx, 0, fy, cy, 0, 0, 1}; }
};

/// Full-frame buffers draw calls reuse, so rendering allocates only on the first frame.
struct RenderScratch {
	cv::Mat tile; ///< CV_8UC3: a plane's warped texture
	cv::Mat mask; ///< CV_8UC1: where the plane covers
};

/// Everything needed to render any time t, built once from SimConfig.
class Scene
{
public:
	explicit Scene(const SimConfig &config);

	[[nodiscard]] const CameraIntrinsics &intrinsics() const { return intrinsics_; }
	[[nodiscard]] Pose left_pose(double t) const;
	[[nodiscard]] Pose right_pose(double t) const;
	[[nodiscard]] const std::vector<Mover> &movers() const { return movers_; }
	[[nodiscard]] const std::string &texture_origin() const { return texture_origin_; }

	/// Draws the view from `pose` at time t into `image` (CV_8UC3, preallocated); fills `object_ids`
	/// (CV_8UC1) and `depth` (CV_32FC1) when they are non-empty.
	void render(double t, const Pose &pose, cv::Mat &image, cv::Mat &object_ids, cv::Mat &depth,
		    RenderScratch &scratch) const;
	/// Fills the truth for the left camera at time t (pose, movers' states).
	void fill_truth(double t, FrameTruth &truth) const;
	/// A mover's bottom-centre position and velocity in the world at time t.
	[[nodiscard]] std::pair<cv::Vec3d, cv::Vec3d> mover_state(const Mover &mover, double t) const;
	/// The left camera's centre in the world at time t, and its velocity.
	[[nodiscard]] std::pair<cv::Vec3d, cv::Vec3d> camera_centre(double t) const;

private:
	void draw_plane(const TexturedPlane &plane, const Pose &pose, cv::Mat &image, cv::Mat &object_ids,
			cv::Mat &depth, RenderScratch &scratch) const;

	SimConfig config_;
	CameraIntrinsics intrinsics_;
	std::vector<TexturedPlane> background_; ///< drawn first, far to near
	std::vector<TexturedPlane> furniture_;	///< static boards standing on the ground, drawn next by depth
	std::vector<Mover> movers_;
	std::string texture_origin_;
	// Camera motion: yaw(t) = yaw_amp sin(2 pi t / period), sway x(t) = sway_amp sin(...), forward speed.
	double yaw_amplitude_rad_ = 0;
	double pitch_amplitude_rad_ = 0;
	double sway_amplitude_m_ = 0;
	double motion_period_s_ = 8;
	// Walking (scene "walk"): z(t) = range (1 - cos(2 pi (t + phase) / period)) / 2, a forward walk that slows
	// and turns back smoothly at the ends; the step's vertical bob and sideways sway on top.
	double walk_range_m_ = 0;
	double walk_period_s_ = 20;
	double walk_phase_s_ = 0;
	double bob_amplitude_m_ = 0;
	double step_frequency_hz_ = 2;
	double wall_z_ = 14;
};

/// Where the sim looks for photographs when SimConfig::texture_dir is empty.
std::vector<std::string> default_texture_dirs();

} // namespace stereod::drivers::sim
