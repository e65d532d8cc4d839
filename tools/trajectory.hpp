#pragma once
// Trajectory accuracy, as seed 001's Tables I-III and the KITTI odometry benchmark report it. Pure: poses in,
// numbers out; the readers and writers of the two file formats are here too.
//   ATE  absolute trajectory error: the estimate aligned to the truth by the best rigid motion (Horn /
//        Umeyama, no scale: stereo is metric), then the translation error per pose
//   RPE  relative pose error over `delta` frames: (truth_i^-1 truth_j)^-1 (est_i^-1 est_j), translation and
//        rotation
//   drift KITTI-style: over every window of `window` frames, the relative translation error over the
//        distance travelled in it, in percent, averaged over windows that moved at all
#include <cstdint>
#include <string>
#include <vector>

#include "core/geometry/rig.hpp"

namespace stereod::tools {

struct StampedPose {
	double t_s = 0;	     ///< seconds (TUM); the frame index for KITTI files
	geometry::Pose pose; ///< world from camera
};

/// TUM RGB-D format: "timestamp tx ty tz qx qy qz qw" per line, '#' comments. Throws naming file:line.
std::vector<StampedPose> read_tum(const std::string &path);
void write_tum(const std::string &path, const std::vector<StampedPose> &poses);
/// KITTI odometry poses: 12 numbers per line (row-major 3x4), one line per frame; t_s = the line index.
std::vector<StampedPose> read_kitti_poses(const std::string &path);

/// Pairs each estimate with the truth nearest in time, within max_dt_s (each truth used once at most).
struct Association {
	std::vector<geometry::Pose> estimate;
	std::vector<geometry::Pose> truth;
	std::vector<double> t_s;
};
Association associate(const std::vector<StampedPose> &estimate, const std::vector<StampedPose> &truth, double max_dt_s);

struct ErrorStats {
	size_t count = 0;
	double rmse = 0, mean = 0, median = 0, std = 0, max = 0;
};
ErrorStats error_stats(std::vector<double> values);

/// The rigid motion A minimising sum |truth_t - A estimate_t|^2 over the positions (Umeyama 1991, no scale).
geometry::Pose align_rigid(const std::vector<geometry::Pose> &estimate, const std::vector<geometry::Pose> &truth);

struct AbsoluteError {
	ErrorStats translation_m;
	geometry::Pose alignment; ///< truth world from estimate world
};
AbsoluteError absolute_trajectory_error(const std::vector<geometry::Pose> &estimate,
					const std::vector<geometry::Pose> &truth);

struct RelativeError {
	ErrorStats translation_m;
	ErrorStats rotation_deg;
};
RelativeError relative_pose_error(const std::vector<geometry::Pose> &estimate, const std::vector<geometry::Pose> &truth,
				  size_t delta);

struct Drift {
	size_t windows = 0;
	double translation_percent = 0; ///< mean over windows of error / distance, x 100
	double rotation_deg_per_m = 0;	///< mean over windows of rotation error / distance
};
Drift drift(const std::vector<geometry::Pose> &estimate, const std::vector<geometry::Pose> &truth, size_t window,
	    double min_distance_m = 0.05);

} // namespace stereod::tools
