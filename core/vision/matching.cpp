#include "core/vision/matching.hpp"

#include <opencv2/features2d.hpp>

namespace stereod::vision
{

std::vector<Match> match_features(const FrameFeatures &prev, const FrameFeatures &cur, const MatchParams &params)
{
	std::vector<Match> matches;
	if (prev.descriptors.empty() || cur.descriptors.empty())
		return matches;
	cv::BFMatcher matcher(cur.norm_type, false);
	std::vector<std::vector<cv::DMatch>> forward;
	matcher.knnMatch(prev.descriptors, cur.descriptors, forward, 2);

	std::vector<int> backward_best;
	if (params.cross_check) {
		std::vector<cv::DMatch> backward;
		matcher.match(cur.descriptors, prev.descriptors, backward);
		backward_best.assign(static_cast<size_t>(cur.descriptors.rows), -1);
		for (const auto &m : backward)
			backward_best[static_cast<size_t>(m.queryIdx)] = m.trainIdx;
	}

	matches.reserve(forward.size());
	for (const auto &candidates : forward) {
		if (candidates.empty())
			continue;
		const cv::DMatch &best = candidates[0];
		if (best.distance > static_cast<float>(params.max_distance))
			continue;
		if (candidates.size() > 1 && best.distance > params.ratio * candidates[1].distance)
			continue;
		if (params.cross_check && backward_best[static_cast<size_t>(best.trainIdx)] != best.queryIdx)
			continue;
		matches.push_back({best.queryIdx, best.trainIdx, best.distance});
	}
	return matches;
}

} // namespace stereod::vision
