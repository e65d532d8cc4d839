#pragma once
// The per-frame and per-pair stages the worker pool runs for seed 000's classification.
//   extract_stage: one frame -> its features (runs for many frames in parallel)
//   pair_stage:    features and motion memory of n-1, features and image of n -> labelled points, the
//                  homography and the memory of n (the only stage that must run in frame order)
#include "core/frame.hpp"
#include "core/result.hpp"
#include "core/vision/classifier.hpp"
#include "core/vision/features.hpp"
#include "core/vision/matching.hpp"
#include "core/vision/temporal.hpp"

namespace stereod::vision {

struct MotionParams {
	bool enabled = true;
	FeatureParams features;
	MatchParams matching;
	ClassifierParams classifier;
	TemporalParams temporal;
};

/// Features of the frame's left image; appends its time as "extract".
FrameFeatures extract_stage(const StereoFrame &frame, const MotionParams &params, std::vector<StageTime> &timing);

/// Matches n-1 to n, classifies (seed 000) and applies the motion memory; fills result.points and result.ego,
/// appends "match" and "classify", and returns frame n's memory for the next call. With no previous frame (the
/// first one, or after a gap the caller chose not to bridge) points and ego stay empty and the memory starts
/// afresh; `prev_tracks` null with `prev` set means the previous memory was lost, and it starts afresh too.
TrackSet pair_stage(const FrameFeatures *prev, const TrackSet *prev_tracks, const FrameFeatures &cur,
		    const StereoFrame &frame, const MotionParams &params, FrameResult &result);

} // namespace stereod::vision
