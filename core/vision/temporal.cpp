#include "core/vision/temporal.hpp"

#include <algorithm>
#include <cmath>

#include "core/vision/ego.hpp"

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
		after.anchor_samples = before.anchor_samples;
		after.last_world = before.last_world;
		after.last_sigma_m = before.last_sigma_m;
		after.last_t_ns = before.last_t_ns;
		after.pooled_frames = before.pooled_frames;
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

AnchorTest advance_anchor(TrackState &state, const std::optional<DepthSample> &depth, bool may_start, int64_t t_ns,
			  const CameraInWorld &camera, const AnchorParams &params)
{
	const AnchorTest kNone;
	const geometry::Pose &world_from_camera = camera.world_from_camera;
	const geometry::Pose &camera_from_world = camera.camera_from_world;
	bool anchored = std::isfinite(state.anchor_world[0]);
	std::optional<cv::Vec3d> world;
	if (depth) {
		world = world_from_camera * depth->xyz_camera;
		if (std::isfinite(state.last_world[0]) && params.max_speed_mps > 0) {
			const cv::Vec3d seen = camera_from_world *
					       cv::Vec3d(state.last_world[0], state.last_world[1], state.last_world[2]);
			const double elapsed_s = static_cast<double>(t_ns - state.last_t_ns) * 1e-9;
			const double leap = std::abs(seen[2] - depth->xyz_camera[2]) - params.max_speed_mps * elapsed_s;
			const double noise = static_cast<double>(state.last_sigma_m) * state.last_sigma_m +
					     depth->sigma_m * depth->sigma_m;
			if (leap > 0 && leap * leap > params.gate * noise)
				anchored = false;
		}
		state.last_world = cv::Vec3f(static_cast<float>((*world)[0]), static_cast<float>((*world)[1]),
					     static_cast<float>((*world)[2]));
		state.last_sigma_m = static_cast<float>(depth->sigma_m);
		state.last_t_ns = t_ns;
	}
	const auto as_float = [](const cv::Vec3d &v) {
		return cv::Vec3f(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]));
	};
	if (!anchored || state.anchor_age > static_cast<uint32_t>(params.max_frames)) {
		state.anchor_world = cv::Vec3f(std::numeric_limits<float>::quiet_NaN(), 0, 0);
		state.anchor_samples = 0;
		if (world && may_start) {
			state.anchor_world = as_float(*world);
			state.anchor_sigma_m = static_cast<float>(depth->sigma_m);
			state.anchor_age = 0;
			state.anchor_samples = 1;
		}
		return kNone;
	}
	if (!world)
		return kNone;
	// This frame's depth against the anchor as it stands: the pooled test's drift and, once the anchor is old
	// enough, the anchored test's statistic (its square).
	const double drift = anchored_depth_drift(state.anchor_world, state.anchor_sigma_m, camera_from_world,
						  depth->xyz_camera[2], depth->sigma_m);
	AnchorTest test;
	if (params.pool_samples > 0 && state.anchor_samples >= static_cast<uint32_t>(params.pool_samples))
		test.drift_sigmas = drift;
	if (state.anchor_age >= static_cast<uint32_t>(params.min_frames)) {
		test.statistic = drift * drift;
		return test;
	}
	if (may_start) { // the mean of the positions so far, and its noise
		const auto m = static_cast<double>(state.anchor_samples);
		cv::Vec3d mean(state.anchor_world[0], state.anchor_world[1], state.anchor_world[2]);
		mean = (mean * m + *world) / (m + 1);
		state.anchor_world = as_float(mean);
		const double variance = static_cast<double>(state.anchor_sigma_m) * state.anchor_sigma_m * m * m +
					depth->sigma_m * depth->sigma_m;
		state.anchor_sigma_m = static_cast<float>(std::sqrt(variance) / (m + 1));
		++state.anchor_samples;
	}
	return test;
}

std::vector<uint8_t> pool_depth_drift(std::span<const cv::Point2f> px, std::span<const float> depth_m,
				      std::span<const double> drift_sigmas, std::span<const uint8_t> held,
				      const DriftPoolParams &params)
{
	const size_t n = std::min({px.size(), depth_m.size(), drift_sigmas.size()});
	std::vector<uint8_t> found(px.size(), 0);
	if (params.radius_px <= 0 || params.min_points <= 0)
		return found;
	std::vector<size_t> with_drift;
	for (size_t i = 0; i < n; ++i)
		if (std::isfinite(drift_sigmas[i]) && std::isfinite(depth_m[i]) && depth_m[i] > 0)
			with_drift.push_back(i);
	if (with_drift.size() < static_cast<size_t>(params.min_points))
		return found;
	// Sorted by column, so that each point looks only at those within the radius across.
	std::sort(with_drift.begin(), with_drift.end(), [&](size_t a, size_t b) { return px[a].x < px[b].x; });
	const double radius2 = params.radius_px * params.radius_px;
	size_t first = 0;
	for (size_t a = 0; a < with_drift.size(); ++a) {
		const size_t i = with_drift[a];
		if (std::abs(drift_sigmas[i]) < params.own_sigmas)
			continue;
		while (px[with_drift[first]].x < px[i].x - static_cast<float>(params.radius_px))
			++first;
		double sum = 0;
		int count = 0;
		for (size_t b = first; b < with_drift.size(); ++b) {
			const size_t j = with_drift[b];
			if (px[j].x > px[i].x + static_cast<float>(params.radius_px))
				break;
			const cv::Point2f d = px[j] - px[i];
			if (static_cast<double>(d.x) * d.x + static_cast<double>(d.y) * d.y > radius2 ||
			    std::abs(depth_m[j] - depth_m[i]) > params.depth_ratio * std::min(depth_m[i], depth_m[j]))
				continue;
			sum += drift_sigmas[j];
			++count;
		}
		const double gate = i < held.size() && held[i] != 0 ? params.hold_sigmas : params.sigmas;
		if (count >= params.min_points && sum * drift_sigmas[i] > 0 &&
		    std::abs(sum) / std::sqrt(static_cast<double>(count)) > gate)
			found[i] = 1;
	}
	return found;
}

std::vector<uint8_t> spread_by_depth(std::span<const cv::Point2f> px, std::span<const float> depth_m,
				     std::span<const uint8_t> found, std::span<const uint8_t> open,
				     const DepthSpreadParams &params)
{
	const size_t n = std::min({px.size(), depth_m.size(), found.size(), open.size()});
	std::vector<uint8_t> spread(px.size(), 0);
	if (params.radius_px <= 0 || params.min_neighbours <= 0)
		return spread;
	std::vector<size_t> sources; // few: the points the test failed this frame
	for (size_t i = 0; i < n; ++i)
		if (found[i] != 0 && std::isfinite(depth_m[i]) && depth_m[i] > 0)
			sources.push_back(i);
	if (sources.size() < static_cast<size_t>(params.min_neighbours))
		return spread;
	const double radius2 = params.radius_px * params.radius_px;
	for (size_t i = 0; i < n; ++i) {
		if (open[i] == 0 || found[i] != 0 || !std::isfinite(depth_m[i]) || depth_m[i] <= 0)
			continue;
		int near = 0;
		for (const size_t s : sources) {
			const cv::Point2f d = px[i] - px[s];
			if (static_cast<double>(d.x) * d.x + static_cast<double>(d.y) * d.y > radius2 ||
			    std::abs(depth_m[i] - depth_m[s]) > params.depth_ratio * std::min(depth_m[i], depth_m[s]))
				continue;
			if (++near >= params.min_neighbours)
				break;
		}
		spread[i] = near >= params.min_neighbours ? 1 : 0;
	}
	return spread;
}

} // namespace stereod::vision
