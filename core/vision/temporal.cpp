#include "core/vision/temporal.hpp"

#include <algorithm>
#include <cmath>

namespace stereod::vision {

TrackSet follow_tracks(const TrackSet *prev, const FollowInput &input, const ClassifierParams &classifier,
		       const TemporalParams &params)
{
	TrackSet out;
	out.t_ns = input.t_ns;
	out.interval_ns = prev != nullptr ? input.t_ns - prev->t_ns : 0;
	if (input.homography != nullptr)
		out.homography = *input.homography;
	out.next_id = prev != nullptr ? prev->next_id : 1;
	out.by_keypoint.resize(input.cur_keypoints);

	double lambda = 0;
	if (prev != nullptr && params.window_s > 0 && input.t_ns > prev->t_ns)
		lambda = std::exp(-static_cast<double>(input.t_ns - prev->t_ns) * 1e-9 / params.window_s);
	const double max_motion2 = classifier.dynamic_max_motion_px * classifier.dynamic_max_motion_px;
	std::vector<bool> prev_taken(prev != nullptr ? prev->by_keypoint.size() : 0, false);

	const bool can_follow =
		prev != nullptr && input.homography != nullptr && input.texture_agrees.size() == input.matches.size();
	for (size_t i = 0; can_follow && i < input.matches.size() && i < input.pairs.size(); ++i) {
		const auto p = static_cast<size_t>(input.matches[i].prev);
		const auto c = static_cast<size_t>(input.matches[i].cur);
		if (p >= prev->by_keypoint.size() || c >= out.by_keypoint.size() || prev_taken[p])
			continue;
		const PointPair &pair = input.pairs[i];
		const bool use_prediction = input.predicted.size() == input.matches.size();
		const cv::Point2f own =
			pair.cur - (use_prediction ? input.predicted[i] : project(*input.homography, pair.prev));
		const double own2 = static_cast<double>(own.dot(own));
		if (!std::isfinite(own2) || own2 > max_motion2)
			continue;
		if (input.texture_agrees[i] == 0)
			continue;
		const TrackState &before = prev->by_keypoint[p];
		// A jump away from the track's own recent motion is a mismatch onto a look-alike, not motion.
		if (before.count > 0 && jump_statistic(before, own, classifier) >= params.jump_chi2)
			continue;
		prev_taken[p] = true;
		TrackState &after = out.by_keypoint[c];
		after.id = before.id;
		after.motion = static_cast<float>(lambda) * before.motion + own;
		after.count = static_cast<float>(lambda) * before.count + 1;
		after.noise_weight = static_cast<float>(lambda * lambda) * before.noise_weight + 1;
		after.age = before.age + 1;
		after.anchor_world = before.anchor_world;
		after.anchor_sigma_m = before.anchor_sigma_m;
		after.anchor_age = before.anchor_age + 1;
	}
	for (auto &state : out.by_keypoint)
		if (state.id == 0)
			state.id = out.next_id++;
	return out;
}

std::optional<std::vector<cv::Point2f>> predict_positions(const TrackSet &tracks,
							  const std::vector<cv::KeyPoint> &keypoints, int64_t next_t_ns)
{
	if (!tracks.homography || tracks.interval_ns <= 0 || tracks.by_keypoint.size() != keypoints.size())
		return std::nullopt;
	const int64_t interval = next_t_ns - tracks.t_ns;
	// Within half an interval of the last one: the same cadence, so the same motion per frame.
	if (2 * interval < tracks.interval_ns || 2 * interval > 3 * tracks.interval_ns)
		return std::nullopt;
	std::vector<cv::Point2f> predicted(keypoints.size());
	for (size_t i = 0; i < keypoints.size(); ++i) {
		const TrackState &state = tracks.by_keypoint[i];
		const cv::Point2f own = state.count > 0 ? state.motion / state.count : cv::Point2f(0, 0);
		predicted[i] = project(*tracks.homography, keypoints[i].pt) + own;
	}
	return predicted;
}

double jump_statistic(const TrackState &before, cv::Point2f own, const ClassifierParams &classifier)
{
	const cv::Point2f innovation = own - before.motion / before.count;
	const double sigma2 = classifier.reprojection_sigma_px * classifier.reprojection_sigma_px;
	const double count = static_cast<double>(before.count);
	const double variance = 2.0 * sigma2 * (1.0 + static_cast<double>(before.noise_weight) / (count * count));
	return static_cast<double>(innovation.dot(innovation)) / variance;
}

bool memory_says_moving(const TrackState &state, const ClassifierParams &classifier, const TemporalParams &params)
{
	if (params.window_s <= 0 || state.age < static_cast<uint32_t>(std::max(params.min_age, 1)) ||
	    state.noise_weight <= 0)
		return false;
	const double sigma2 = classifier.reprojection_sigma_px * classifier.reprojection_sigma_px;
	const double r2 = static_cast<double>(state.motion.dot(state.motion));
	return r2 / (sigma2 * static_cast<double>(state.noise_weight)) > params.chi2;
}

int promote_remembered_movers(std::span<PointLabel> labels, std::span<const Match> matches, const TrackSet &tracks,
			      const ClassifierParams &classifier, const TemporalParams &params,
			      std::span<const uint8_t> looser, double looser_chi2)
{
	TemporalParams loose = params;
	loose.chi2 = std::min(params.chi2, looser_chi2); // clearing either gate is clearing the lower one
	int promoted = 0;
	for (size_t i = 0; i < labels.size() && i < matches.size(); ++i) {
		const auto c = static_cast<size_t>(matches[i].cur);
		if (labels[i] == PointLabel::Dynamic || c >= tracks.by_keypoint.size())
			continue;
		const bool is_loose = i < looser.size() && looser[i] != 0 && labels[i] == PointLabel::Static;
		if (memory_says_moving(tracks.by_keypoint[c], classifier, is_loose ? loose : params)) {
			labels[i] = PointLabel::Dynamic;
			++promoted;
		}
	}
	return promoted;
}

} // namespace stereod::vision
