#pragma once
// Seed 001's keyframe selection (section III.C.2, eqs. 6-7): a frame becomes a keyframe when the camera has
// really moved since the last keyframe (rotation or translation past a threshold, eq. 6) and the static scene
// it sees has changed: the static co-visibility index
//     mu = |N1 ∩ N2| / |N1|                                                            (eq. 7)
// (N1: the static points observed in this frame, N2: those observed in the last keyframe) is below a
// threshold, and at least `min_new_points` (the seed: 15) of this frame's static points are new. A camera that
// moves back and forth over the same view therefore makes no new keyframes. Keyframes are what the static
// map can be built from (seed 001 Fig. 6) and are marked in the frame message (`ego.keyframe`).
//
// "Observed in both" is decided geometrically, as a SLAM system's map points would: a static point of this
// frame was seen by the keyframe when one of the keyframe's static points, carried into this camera by the
// two poses, projects within `match_px` of it at the same depth (within `depth_tolerance` of it). Track ids
// would not do: a frame-to-frame track survives about half of the frames on the sim's walk (ORB re-detects
// other corners), so they undercount what the two frames share.
#include <cstdint>
#include <span>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rig.hpp"

namespace stereod::vision {

struct KeyframeParams {
	bool enabled = true;
	double min_translation_m = 0.10; ///< eq. 6's t_th
	double min_rotation_deg = 5.0;	 ///< eq. 6's theta_th
	double max_covisibility = 0.7;	 ///< eq. 7: a keyframe needs mu below this
	int min_new_points = 15;	 ///< and at least this many static points the last keyframe did not see
	double match_px = 3.0;		 ///< a keyframe point projected this close to a point is the same point...
	double depth_tolerance = 0.1;	 ///< ...when their depths differ by less than this fraction
};

/// A static point as a frame observed it: pixel in the (rectified) left image and camera coordinates.
struct StaticObservation {
	cv::Point2f px;
	cv::Vec3f xyz;
};

/// The last keyframe, as the memory carries it.
struct Keyframe {
	uint64_t seq = 0;
	geometry::Pose world_from_camera;
	std::vector<cv::Vec3f> static_world; ///< its static points with depth, in the world
};

/// Eq. 7: the fraction of `current` (this frame's static points with depth, camera at `world_from_curr`) that
/// `keyframe` also observed. 0 when `current` is empty.
double covisibility(std::span<const StaticObservation> current, const geometry::Pose &world_from_curr,
		    const Keyframe &keyframe, const geometry::StereoRig &rig, const KeyframeParams &params);

struct KeyframeDecision {
	bool keyframe = false;
	bool moved = false; ///< eq. 6
	double covisibility = 0;
	int new_points = 0;
	double translation_m = 0;
	double rotation_deg = 0;
};

/// Whether the frame at `world_from_curr` observing `current` is a new keyframe after `last`.
KeyframeDecision decide_keyframe(const Keyframe &last, const geometry::Pose &world_from_curr,
				 std::span<const StaticObservation> current, const geometry::StereoRig &rig,
				 const KeyframeParams &params);

/// The keyframe a frame makes: its pose and its static points carried into the world.
Keyframe make_keyframe(uint64_t seq, const geometry::Pose &world_from_curr, std::span<const StaticObservation> current);

} // namespace stereod::vision
