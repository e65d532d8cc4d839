#pragma once
// The per-frame and per-pair stages the worker pool runs.
//   extract_stage: one frame -> its features, and with a calibrated stereo (or depth) source each keypoint's
//                  3D point (runs for many frames in parallel)
//   pair_stage:    features and memory of n-1, features and image of n -> labelled points, the camera's
//                  motion (homography; stereo: the metric pose) and the memory of n (runs in frame order)
//
// Labels with depth (docs/geometry.md): `label_method` chooses
//   seed000    seed 000's homography chain alone (the monocular method)
//   geometric  seed 001's check with the stereo pose: a point the pose and its depth explain is static, one
//              they do not is dynamic; a match whose two ends look different (seed 000's texture test) stays
//              uncertain. Points without depth are judged by eq. 1 alone.
//   combined   geometric where the point has depth; without depth, seed 000 and eq. 1 must agree
#include <optional>

#include "core/frame.hpp"
#include "core/geometry/rig.hpp"
#include "core/result.hpp"
#include "core/vision/classifier.hpp"
#include "core/vision/dense_motion.hpp"
#include "core/vision/ego.hpp"
#include "core/vision/features.hpp"
#include "core/vision/keyframes.hpp"
#include "core/vision/matching.hpp"
#include "core/vision/stereo.hpp"
#include "core/vision/temporal.hpp"

namespace stereod::vision {

enum class LabelMethod : uint8_t { Seed000, Geometric, Combined };

struct MotionParams {
	bool enabled = true;
	FeatureParams features;
	MatchParams matching;
	ClassifierParams classifier;
	TemporalParams temporal;
	StereoParams stereo;
	EgoParams ego;
	LabelMethod label_method = LabelMethod::Combined;
	GroupParams groups;
	DenseFlowParams dense; ///< the flow the groups take their members from (sparse: the temporal matches)
	PersonPriorParams prior;
	KeyframeParams keyframes;
	/// The source's rectified calibration; without it there is no depth and no metric pose.
	std::optional<geometry::StereoRig> rig;
};

/// Features of the frame's left image and, with a calibrated stereo or depth source, their 3D points;
/// appends "extract" (and "stereo": the right eye's features and the matching).
FrameFeatures extract_stage(const StereoFrame &frame, const MotionParams &params, std::vector<StageTime> &timing);

/// What a worker keeps from one frame's pair stage to the next so that the stages do not make it again:
/// Affinity Propagation's buffers and the DIS flow object. One per worker thread, owned by it and never
/// shared; a new one only costs the first frame some allocations.
struct StageWorkspace {
	AffinityPropagation affinity;
	cv::Ptr<cv::DISOpticalFlow> dis; ///< made at the first frame with `groups.flow = "dis"`
};

/// Matches n-1 to n, classifies and applies the motion memory; fills result.points and result.ego,
/// appends "match", "classify" (and "pose"), and returns frame n's memory for the next call. With no previous
/// frame (the first one, or after a gap the caller chose not to bridge) points stay empty and the memory
/// starts afresh; `prev_tracks` null with `prev` set means the previous memory was lost, and it starts afresh
/// too. A stereo frame's ego then has the identity pose as the world's origin. With matching.follow_lost it
/// grows `cur` by the lost corners it keeps, so frame n's features are final only once it returns.
TrackSet pair_stage(const FrameFeatures *prev, const TrackSet *prev_tracks, FrameFeatures &cur,
		    const StereoFrame &frame, const MotionParams &params, FrameResult &result,
		    StageWorkspace &workspace);

} // namespace stereod::vision
