#pragma once
// The per-frame and per-pair stages the worker pool runs for seed 000's classification.
//   extract_stage: one frame -> its features (runs for many frames in parallel)
//   pair_stage:    features of n-1 and n, image n -> labelled points and the homography
#include "core/frame.hpp"
#include "core/result.hpp"
#include "core/vision/classifier.hpp"
#include "core/vision/features.hpp"
#include "core/vision/matching.hpp"

namespace stereod::vision {

struct MotionParams {
	bool enabled = true;
	FeatureParams features;
	MatchParams matching;
	ClassifierParams classifier;
};

/// Features of the frame's left image; appends its time as "extract".
FrameFeatures extract_stage(const StereoFrame &frame, const MotionParams &params, std::vector<StageTime> &timing);

/// Matches n-1 to n and classifies; fills result.points and result.ego and appends "match" and "classify".
/// With no previous frame (the first one, or after a gap the caller chose not to bridge) it leaves them empty.
void pair_stage(const FrameFeatures *prev, const FrameFeatures &cur, const StereoFrame &frame,
		const MotionParams &params, FrameResult &result);

} // namespace stereod::vision
