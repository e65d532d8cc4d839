#include "core/vision/motion_stages.hpp"

#include "core/stage_timer.hpp"

namespace stereod::vision {

FrameFeatures extract_stage(const StereoFrame &frame, const MotionParams &params, std::vector<StageTime> &timing)
{
	StageTimer timer(timing, "extract");
	return extract_features(frame.left, params.features, params.classifier.colour_radius);
}

TrackSet pair_stage(const FrameFeatures *prev, const TrackSet *prev_tracks, const FrameFeatures &cur,
		    const StereoFrame &frame, const MotionParams &params, FrameResult &result)
{
	FollowInput follow;
	follow.cur_keypoints = cur.keypoints.size();
	follow.t_ns = frame.device_ns;
	if (prev == nullptr)
		return follow_tracks(nullptr, follow, params.classifier, params.temporal);
	std::vector<Match> matches;
	{
		StageTimer timer(result.timing, "match");
		const auto predicted = prev_tracks != nullptr && params.matching.search_radius_px > 0
					       ? predict_positions(*prev_tracks, prev->keypoints, frame.device_ns)
					       : std::nullopt;
		matches = predicted ? match_features_guided(*prev, cur, *predicted, params.matching)
				    : match_features(*prev, cur, params.matching);
	}
	StageTimer timer(result.timing, "classify");
	std::vector<PointPair> pairs;
	pairs.reserve(matches.size());
	for (const auto &m : matches) {
		const auto p = static_cast<size_t>(m.prev);
		const auto c = static_cast<size_t>(m.cur);
		pairs.push_back({prev->keypoints[p].pt, cur.keypoints[c].pt, prev->colours[p], cur.colours[c]});
	}
	std::vector<uint8_t> known_moving(matches.size(), 0);
	if (prev_tracks != nullptr) {
		for (size_t i = 0; i < matches.size(); ++i) {
			const auto p = static_cast<size_t>(matches[i].prev);
			known_moving[i] =
				p < prev_tracks->by_keypoint.size() &&
				memory_says_moving(prev_tracks->by_keypoint[p], params.classifier, params.temporal);
		}
	}
	Classification classification = classify(pairs, frame.left, params.classifier, known_moving);
	follow.matches = matches;
	follow.pairs = pairs;
	follow.homography = classification.homography ? &*classification.homography : nullptr;
	follow.texture_agrees = classification.texture_agrees;
	TrackSet tracks = follow_tracks(prev_tracks, follow, params.classifier, params.temporal);
	promote_remembered_movers(classification.labels, matches, tracks, params.classifier, params.temporal);
	result.points.reserve(pairs.size());
	for (size_t i = 0; i < pairs.size(); ++i) {
		LabelledPoint point;
		point.u = pairs[i].cur.x;
		point.v = pairs[i].cur.y;
		point.prev_u = pairs[i].prev.x;
		point.prev_v = pairs[i].prev.y;
		point.label = classification.labels[i];
		point.track = tracks.by_keypoint[static_cast<size_t>(matches[i].cur)].id;
		result.points.push_back(point);
	}
	if (classification.homography) {
		EgoMotion ego;
		for (int r = 0; r < 3; ++r)
			for (int c = 0; c < 3; ++c)
				ego.homography[static_cast<size_t>(r * 3 + c)] = (*classification.homography)(r, c);
		ego.inliers = classification.homography_inliers;
		result.ego = ego;
	}
	return tracks;
}

} // namespace stereod::vision
