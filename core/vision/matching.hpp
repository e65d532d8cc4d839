#pragma once
// Frame n-1 to frame n descriptor matching.
#include <vector>

#include "core/vision/features.hpp"

namespace stereod::vision {

struct MatchParams {
	float ratio = 0.8F;	 ///< Lowe's ratio test on the two nearest neighbours; 1 disables it
	bool cross_check = true; ///< keep a match only if it is also the best match backwards
	int max_distance = 64;	 ///< Hamming bits (ORB); matches farther apart are dropped
};

struct Match {
	int prev = 0; ///< index into the previous frame's keypoints
	int cur = 0;  ///< index into this frame's keypoints
	float distance = 0;
};

/// Brute-force matching with ratio test and cross check.
std::vector<Match> match_features(const FrameFeatures &prev, const FrameFeatures &cur, const MatchParams &params);

} // namespace stereod::vision
