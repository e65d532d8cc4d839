#include "core/vision/motion_stages.hpp"

#include <algorithm>
#include <cmath>
#include <future>
#include <limits>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/stage_timer.hpp"
#include "core/vision/prior_model.hpp"

namespace stereod::vision {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

cv::Mat grey_of(const cv::Mat &image)
{
	if (image.channels() == 1)
		return image;
	cv::Mat grey;
	cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
	return grey;
}

/// Each keypoint's 3D point from a depth image (CV_32FC1, metres, 0 = unknown) registered to the left image.
std::vector<cv::Vec3f> points_from_depth(const std::vector<cv::KeyPoint> &keypoints, const cv::Mat &depth,
					 const geometry::StereoRig &rig)
{
	std::vector<cv::Vec3f> xyz(keypoints.size(), cv::Vec3f(kNaN, kNaN, kNaN));
	for (size_t i = 0; i < keypoints.size(); ++i) {
		const int x = static_cast<int>(std::lround(keypoints[i].pt.x));
		const int y = static_cast<int>(std::lround(keypoints[i].pt.y));
		if (x < 0 || y < 0 || x >= depth.cols || y >= depth.rows)
			continue;
		const float z = depth.at<float>(y, x);
		if (!(z > 0) || !std::isfinite(z))
			continue;
		xyz[i] = cv::Vec3f(rig.back_project(keypoints[i].pt.x, keypoints[i].pt.y, z));
	}
	return xyz;
}

/// The depth of each grid cell of the dense flow (when the groups use it), made once per frame here rather
/// than for both frames of every pair.
void add_cell_depths(FrameFeatures &features, cv::Size size, const MotionParams &params)
{
	if (!params.groups.enabled || params.dense.method == GroupFlow::Sparse)
		return;
	const int step = std::max(params.dense.step_px, 1);
	features.cell_depth =
		cell_depths(features.keypoints, features.xyz, size.width / step, size.height / step, params.dense);
}

/// Whether the groups cluster followed points beside the matched ones: the sparse flow without a metric pose,
/// where seed 002's split decides the members. (With a pose the labels decide, and a followed point has
/// none; nor has it the depth the pose's prediction needs.)
bool follows_unmatched(const MotionParams &params, bool metric)
{
	return params.groups.enabled && params.groups.follow_unmatched && params.dense.method == GroupFlow::Sparse &&
	       params.groups.members != GroupMembers::Labels && !metric &&
	       (params.matching.rescue || params.matching.subpixel);
}

/// A lost corner continues a track only once it is a frame old: a keypoint matched nowhere yet may be a
/// one-frame look-alike, and following it would start a chain.
constexpr uint32_t kLostCornerMinAge = 1;
/// How far from its predecessor's disparity a lost corner's is searched. A mover 2 m away closing at 2 m/s
/// changes its disparity by about 2 px a frame at 30 fps (f b = 111 px m: the sim at 1024 px wide, a 12 cm
/// baseline).
constexpr double kLostCornerDisparitySlackPx = 8;

/// Keeps the lost corners among `followed` (lost_corners; only those whose track is kLostCornerMinAge old) as
/// keypoints of `cur`: the previous keypoint's size, angle and descriptor at the place Lucas-Kanade found, this
/// frame's colour there and, where the frame has depth, its depth there. A corner with no clean depth in a frame that
/// has depth is not kept: at a mover's outline the window straddles its edge, and a point without depth takes no part
/// in the metric tests. Appends the matches that continue the tracks and takes the kept points out of `followed`.
void keep_lost_corners(const FrameFeatures &prev, const TrackSet &prev_tracks, FrameFeatures &cur,
		       const StereoFrame &frame, const MotionParams &params, std::vector<FollowedPoint> &followed,
		       std::vector<Match> &matches)
{
	std::vector<FollowedPoint> old_enough;
	for (const FollowedPoint &f : followed)
		if (prev_tracks.by_keypoint[static_cast<size_t>(f.prev)].age >= kLostCornerMinAge)
			old_enough.push_back(f);
	const std::vector<FollowedPoint> lost =
		lost_corners(old_enough, cur, matches, params.matching.follow_lost_clear_px);
	if (lost.empty())
		return;
	const bool has_depth = !cur.xyz.empty() && params.rig;
	const bool from_stereo = has_depth && !frame.right.empty() && params.stereo.enabled;
	const cv::Mat right_grey = from_stereo && cur.right_grey.empty() ? grey_of(frame.right) : cur.right_grey;
	const bool on_edge_kept = cur.depth_on_edge.size() == cur.xyz.size();
	RowSearchBuffers buffers;
	std::vector<int> kept_prev;
	for (const FollowedPoint &f : lost) {
		const auto p = static_cast<size_t>(f.prev);
		cv::KeyPoint keypoint = prev.keypoints[p];
		keypoint.pt = f.at;
		std::optional<cv::Vec3f> xyz;
		if (from_stereo) {
			// Searched near the predecessor's disparity where it had one: a frame apart the point's
			// depth changes little, and a look-alike farther along the row is no candidate.
			StereoParams around = params.stereo;
			if (p < prev.xyz.size() && prev.xyz[p][2] > 0) {
				const double d = params.rig->fx * params.rig->baseline_m / prev.xyz[p][2];
				around.min_disparity_px =
					std::max(params.stereo.min_disparity_px, d - kLostCornerDisparitySlackPx);
				around.max_disparity_px =
					std::min(params.stereo.max_disparity_px, d + kLostCornerDisparitySlackPx);
			}
			xyz = clean_row_depth(cur.grey, right_grey, f.at, *params.rig, around, buffers);
		} else if (has_depth && !frame.depth.empty())
			if (const cv::Vec3f q = points_from_depth({keypoint}, frame.depth, *params.rig)[0];
			    std::isfinite(q[2]))
				xyz = q;
		if (has_depth && !xyz)
			continue;
		// All of the corner is measured before any of it is added: a failure leaves `cur` consistent.
		const cv::Vec3f colour = sample_colour(frame.left, f.at, params.classifier.colour_radius);
		const int index = static_cast<int>(cur.keypoints.size());
		cur.keypoints.push_back(keypoint);
		cur.descriptors.push_back(prev.descriptors.row(static_cast<int>(p)));
		cur.colours.push_back(colour);
		if (has_depth) {
			cur.xyz.push_back(*xyz);
			if (on_edge_kept)
				cur.depth_on_edge.push_back(0);
		}
		matches.push_back({f.prev, index, 0});
		kept_prev.push_back(f.prev);
	}
	std::sort(kept_prev.begin(), kept_prev.end());
	std::erase_if(followed, [&](const FollowedPoint &f) {
		return std::binary_search(kept_prev.begin(), kept_prev.end(), f.prev);
	});
}

/// Whether `at` lies inside one of the published groups' boxes.
bool inside_a_box(cv::Point2f at, const std::vector<TargetGroup> &groups)
{
	return std::any_of(groups.begin(), groups.end(), [&](const TargetGroup &g) { return box_holds(g, at); });
}

/// Whether keypoint `p` of the previous frame was labelled dynamic or failed a geometric test there.
bool flagged_before(const TrackSet *prev_tracks, size_t p)
{
	return prev_tracks != nullptr && p < prev_tracks->dynamic_by_keypoint.size() &&
	       prev_tracks->dynamic_by_keypoint[p] != 0;
}

/// Whether keypoint `k`'s depth came from a stereo window across a depth edge (FrameFeatures::depth_on_edge).
bool on_depth_edge(const FrameFeatures &features, size_t k)
{
	return k < features.depth_on_edge.size() && features.depth_on_edge[k] != 0;
}

/// A point's own motion: where it is minus where the static scene model puts it (the pose's prediction from
/// its depth, else the homography); NaN without either.
cv::Point2f own_motion(const PointPair &pair, cv::Point2f predicted, const std::optional<cv::Matx33d> &homography)
{
	if (std::isfinite(predicted.x))
		return pair.cur - predicted;
	if (homography) {
		const cv::Vec3d h = *homography * cv::Vec3d(pair.prev.x, pair.prev.y, 1);
		if (h[2] != 0)
			return pair.cur - cv::Point2f(static_cast<float>(h[0] / h[2]), static_cast<float>(h[1] / h[2]));
	}
	return {kNaN, kNaN};
}

/// The own motion keypoint `p` of the previous frame had (NaN when unknown).
cv::Point2f own_motion_before(const TrackSet *prev_tracks, size_t p)
{
	if (prev_tracks == nullptr || p >= prev_tracks->residual_by_keypoint.size())
		return {kNaN, kNaN};
	return prev_tracks->residual_by_keypoint[p];
}

/// The label a point gets from seed 000's label, the geometric test and whether its two ends look alike.
PointLabel combine(LabelMethod method, PointLabel seed, const GeometricTest &test, bool has_prev_depth,
		   bool texture_agrees)
{
	if (method == LabelMethod::Seed000 || test.dof == 0)
		return method == LabelMethod::Geometric ? PointLabel::Uncertain : seed;
	if (!texture_agrees)
		return PointLabel::Uncertain; // seed 000's mismatch test: the two ends are not the same surface
	if (method == LabelMethod::Geometric || has_prev_depth)
		return test.moving ? PointLabel::Dynamic : PointLabel::Static;
	// Combined, no depth: eq. 1 alone cannot see motion along the epipolar line, and the homography cannot
	// explain parallax; only where both agree is the label kept.
	if (seed == PointLabel::Dynamic && test.moving)
		return PointLabel::Dynamic;
	if (seed == PointLabel::Static && !test.moving)
		return PointLabel::Static;
	return PointLabel::Uncertain;
}

/// The prior's regions as the frame message carries them.
void publish_people(std::span<const PriorRegion> regions, FrameResult &result)
{
	result.people.clear();
	result.objects.clear();
	for (const PriorRegion &r : regions)
		(r.category == PriorCategory::Dynamic ? result.people : result.objects)
			.push_back({{r.box.x, r.box.y, r.box.x + r.box.width, r.box.y + r.box.height},
				    r.score,
				    r.age_frames,
				    r.class_id});
}

/// A frame's static points with depth, for the keyframe selection.
std::vector<StaticObservation> static_observations(std::span<const LabelledPoint> points)
{
	std::vector<StaticObservation> observed;
	for (const LabelledPoint &p : points)
		if (p.label == PointLabel::Static && p.xyz_m)
			observed.push_back({{p.u, p.v}, {(*p.xyz_m)[0], (*p.xyz_m)[1], (*p.xyz_m)[2]}});
	return observed;
}

void fill_pose(EgoMotion &ego, const geometry::Pose *prev_from_curr, const geometry::Pose &world_from_curr)
{
	if (prev_from_curr != nullptr)
		ego.t_prev_curr = prev_from_curr->matrix();
	ego.t_world_curr = world_from_curr.matrix();
}

/// The anchored depth test (docs/geometry.md): each followed point's depth against its track's first
/// measured position carried by the camera's motion since; points that drifted are dynamic. New tracks, and
/// old anchors, are (re-)anchored from this frame's depth. Marks the points that failed in `failed` (which
/// the per-frame test has filled before) and returns, per match, those the finds spread to and those the
/// pooled drift test found (empty when `ego.anchor_spread_px` is 0).
std::vector<uint8_t> anchor_tracks(TrackSet &tracks, std::span<const Match> matches, const FrameFeatures &cur,
				   const geometry::Pose &world_from_curr, Classification &classification,
				   const geometry::StereoRig &rig, const MotionParams &params,
				   const TrackSet &prev_tracks, std::vector<uint8_t> &failed)
{
	failed.resize(matches.size(), 0);
	// Per match for the spread and the pooled test, kept only when one is on: the image position, the depth,
	// found by the test, not tested this frame, the signed drift.
	const bool spreading = params.ego.anchor_spread_px > 0;
	const bool pooling = spreading && params.ego.anchor_pool_samples > 0;
	const size_t kept = spreading ? matches.size() : 0;
	std::vector<cv::Point2f> px(kept);
	std::vector<float> depth_m(kept, std::numeric_limits<float>::quiet_NaN());
	std::vector<uint8_t> found(kept, 0), open(kept, 0);
	std::vector<double> drift(pooling ? matches.size() : 0, std::numeric_limits<double>::quiet_NaN());
	const double gate = chi2_quantile(1, params.ego.chi2_quantile);
	const AnchorParams anchor{params.ego.anchor_min_frames, params.ego.anchor_max_frames,
				  params.ego.anchor_max_speed_mps, gate, pooling ? params.ego.anchor_pool_samples : 0};
	const bool have_texture = classification.texture_agrees.size() == matches.size();
	const CameraInWorld camera(world_from_curr);
	for (size_t i = 0; i < matches.size(); ++i) {
		const auto c = static_cast<size_t>(matches[i].cur);
		if (c >= tracks.by_keypoint.size() || c >= cur.xyz.size())
			continue;
		const cv::Vec3f &xyz = cur.xyz[c];
		std::optional<DepthSample> depth;
		if (std::isfinite(xyz[2]) && xyz[2] > 0)
			depth = DepthSample{cv::Vec3d(xyz[0], xyz[1], xyz[2]),
					    rig.depth_sigma(xyz[2], params.stereo.disparity_sigma_px)};
		const AnchorTest test =
			advance_anchor(tracks.by_keypoint[c], depth, classification.labels[i] != PointLabel::Dynamic,
				       tracks.t_ns, camera, anchor);
		if (spreading) {
			px[i] = cur.keypoints[c].pt;
			if (depth)
				depth_m[i] = xyz[2];
			open[i] = std::isnan(test.statistic) && classification.labels[i] != PointLabel::Dynamic ? 1 : 0;
		}
		if (pooling && classification.labels[i] != PointLabel::Dynamic && !on_depth_edge(cur, c))
			drift[i] = test.drift_sigmas;
		if (!(test.statistic > gate) || (have_texture && classification.texture_agrees[i] == 0))
			continue;
		// Like the per-frame test, confirmed by a failure in the frame before (ego.confirm_frames).
		failed[i] = 1;
		if (params.ego.confirm_frames <= 1 ||
		    flagged_before(&prev_tracks, static_cast<size_t>(matches[i].prev))) {
			classification.labels[i] = PointLabel::Dynamic;
			if (spreading)
				found[i] = 1;
		}
	}
	if (!spreading)
		return {};
	// The pooled test's finds, confirmed on the same track in the frame before, are output-only like the
	// spread; they also seed it, so the young tracks beside them follow.
	std::vector<uint8_t> pooled;
	if (pooling) {
		// A track confirmed in the frames before holds at the lower gate.
		std::vector<uint8_t> held(matches.size(), 0);
		for (size_t i = 0; i < matches.size(); ++i) {
			const auto c = static_cast<size_t>(matches[i].cur);
			held[i] = c < tracks.by_keypoint.size() && tracks.by_keypoint[c].pooled_frames >= 2 ? 1 : 0;
		}
		pooled = pool_depth_drift(px, depth_m, drift, held,
					  {params.ego.anchor_pool_px, params.ego.anchor_spread_depth,
					   params.ego.anchor_pool_min, params.ego.anchor_pool_sigmas, 0.5,
					   params.ego.anchor_pool_hold_sigmas});
		for (size_t i = 0; i < matches.size(); ++i) {
			const auto c = static_cast<size_t>(matches[i].cur);
			if (c >= tracks.by_keypoint.size())
				continue;
			TrackState &state = tracks.by_keypoint[c];
			state.pooled_frames = pooled[i] != 0
						      ? static_cast<uint8_t>(std::min(state.pooled_frames + 1, 255))
						      : uint8_t{0};
			pooled[i] = state.pooled_frames >= 2 && found[i] == 0 ? 1 : 0;
			if (pooled[i] != 0) {
				found[i] = 1;
				open[i] = 0;
			}
		}
	}
	std::vector<uint8_t> spread = spread_by_depth(
		px, depth_m, found, open,
		{params.ego.anchor_spread_px, params.ego.anchor_spread_depth, params.ego.anchor_spread_min});
	for (size_t i = 0; i < pooled.size(); ++i)
		spread[i] = spread[i] != 0 || pooled[i] != 0 ? 1 : 0;
	return spread;
}

} // namespace

FrameFeatures extract_stage(const StereoFrame &frame, const MotionParams &params, std::vector<StageTime> &timing)
{
	FrameFeatures features;
	cv::Mat grey;
	// A source with both eyes is measured by stereo even when it also has a depth image (the sim's depth
	// is its ground truth); a depth image alone (RGB-D) gives the points directly.
	const bool stereo = params.rig && !frame.right.empty() && params.stereo.enabled;
	const bool right_wanted = stereo && right_features_wanted(params.stereo, frame.sequence);
	cv::Mat right_grey;
	FrameFeatures right;
	// The sub-pixel step and the rescue follow points on the grey image by Lucas-Kanade in the pair stage.
	const bool follows_by_image = params.matching.subpixel || params.matching.rescue;
	{
		StageTimer timer(timing, "extract");
		grey = grey_of(frame.left);
		// The right eye's features (every frame with stereo.right_features, else the health frames) are found
		// beside the left's, on a thread of their own: where a core is free the frame then waits for the
		// longer of the two, not their sum, so the health frames do not make the latency's tail. (A thread,
		// not OpenCV's parallel_for_: ThreadSanitizer cannot see that pool's hand-off.)
		std::future<FrameFeatures> right_eye;
		if (right_wanted) {
			right_grey = grey_of(frame.right);
			right_eye = std::async(std::launch::async, [&] {
				return extract_features(frame.right, params.features, params.classifier.colour_radius,
							&right_grey);
			});
		}
		features = extract_features(frame.left, params.features, params.classifier.colour_radius, &grey);
		if (right_eye.valid())
			right = right_eye.get();
		if (follows_by_image)
			// A grey frame's image is a pool buffer that the next capture overwrites: keep a copy.
			features.grey = grey.data == frame.left.data ? grey.clone() : grey;
	}
	if (follows_by_image) {
		StageTimer timer(timing, "pyramid");
		features.grey_pyramid = lk_pyramid(grey, params.matching);
	}
	if (params.groups.enabled && params.dense.method != GroupFlow::Sparse) {
		StageTimer timer(timing, "flow_image");
		features.flow_image = dense_flow_image(grey, params.dense);
	}
	if (params.prior.enabled &&
	    frame.sequence % static_cast<uint64_t>(std::max(params.prior.every_n_frames, 1)) == 0) {
		StageTimer timer(timing, "prior");
		if (params.prior.detector == PriorDetector::Hog)
			features.people = detect_people(grey, params.prior);
		else if (params.prior.model) // colour where the frame has 8-bit colour; a deeper image as grey
			features.people = params.prior.model->detect(frame.left.depth() == CV_8U ? frame.left : grey,
								     params.prior.margin);
		else // the daemon loads the model at start; a caller that did not gets no regions, not HOG's
			features.people = std::vector<PriorRegion>{};
	}
	if (!params.rig)
		return features;
	if (!stereo && !frame.depth.empty()) {
		StageTimer timer(timing, "depth");
		features.xyz = points_from_depth(features.keypoints, frame.depth, *params.rig);
		add_cell_depths(features, frame.left.size(), params);
		return features;
	}
	if (!stereo)
		return features;
	StageTimer timer(timing, "stereo");
	if (right_grey.empty())
		right_grey = grey_of(frame.right);
	if (params.matching.follow_lost && follows_by_image)
		// As the left: a grey frame's image is a pool buffer.
		features.right_grey = right_grey.data == frame.right.data ? right_grey.clone() : right_grey;
	const double scale_step = params.features.detector == Detector::Orb ? params.features.orb_scale : 1.4;
	StereoDepth depth = match_stereo(features, right, grey, right_grey, *params.rig, params.stereo, scale_step);
	features.xyz = std::move(depth.xyz);
	features.depth_on_edge = std::move(depth.on_edge);
	add_cell_depths(features, frame.left.size(), params);
	features.stereo = StereoSummary{
		static_cast<int>(features.keypoints.size()), depth.matched,	depth.candidates, depth.outside_band,
		median_of(std::move(depth.row_differences)), depth.row_searched};
	return features;
}

TrackSet pair_stage(const FrameFeatures *prev, const TrackSet *prev_tracks, FrameFeatures &cur,
		    const StereoFrame &frame, const MotionParams &params, FrameResult &result,
		    StageWorkspace &workspace)
{
	result.stereo = cur.stereo;
	const bool metric = params.rig.has_value() && params.ego.enabled && !cur.xyz.empty();
	FollowInput follow;
	follow.cur_keypoints = cur.keypoints.size();
	follow.t_ns = frame.device_ns;
	if (prev == nullptr || (metric && (prev_tracks == nullptr || !prev_tracks->world_from_camera))) {
		// The first frame (or the memory was lost): with depth, this camera is the world's origin.
		TrackSet tracks = follow_tracks(nullptr, follow, params.classifier, params.temporal);
		if (params.prior.enabled && cur.people) {
			tracks.people = *cur.people;
			publish_people(tracks.people, result);
		}
		if (metric) {
			tracks.world_from_camera = geometry::Pose{};
			EgoMotion ego;
			ego.valid = false;
			ego.reason = "first frame: the world's origin";
			fill_pose(ego, nullptr, *tracks.world_from_camera);
			if (params.keyframes.enabled) {
				ego.keyframe = true; // the world's origin is the first keyframe
				tracks.last_keyframe = Keyframe{frame.sequence, geometry::Pose{}, {}};
			}
			result.ego = ego;
		}
		return tracks;
	}
	std::vector<Match> matches;
	std::vector<FollowedPoint> followed; // for the groups only
	{
		StageTimer timer(result.timing, "match");
		const auto predicted = prev_tracks != nullptr && params.matching.search_radius_px > 0
					       ? predict_positions(*prev_tracks, prev->keypoints, frame.device_ns)
					       : std::nullopt;
		const std::span<const cv::Point2f> prediction =
			predicted ? std::span<const cv::Point2f>(*predicted) : std::span<const cv::Point2f>();
		matches = predicted ? match_features_guided(*prev, cur, *predicted, params.matching)
				    : match_features(*prev, cur, params.matching);
		if (params.matching.rescue) {
			StageTimer rescue_timer(result.timing, "rescue");
			rescue_matches(*prev, cur, prediction, matches, params.matching);
		}
		const bool keeps_lost = params.matching.follow_lost && prev_tracks != nullptr &&
					prev_tracks->by_keypoint.size() == prev->keypoints.size();
		if (keeps_lost || follows_unmatched(params, metric)) {
			StageTimer follow_timer(result.timing, "follow");
			// Without the groups' use of them, only the points a lost corner may continue are followed:
			// those whose track is a frame old (keep_lost_corners).
			std::vector<uint8_t> wanted;
			if (!follows_unmatched(params, metric)) {
				wanted.resize(prev->keypoints.size());
				for (size_t i = 0; i < wanted.size(); ++i)
					wanted[i] = prev_tracks->by_keypoint[i].age >= kLostCornerMinAge ? 1 : 0;
			}
			followed = follow_unmatched(*prev, cur, prediction, matches, params.matching,
						    params.dense.aperture_ratio, wanted);
		}
		if (keeps_lost && !followed.empty()) {
			StageTimer lost_timer(result.timing, "follow_lost");
			keep_lost_corners(*prev, *prev_tracks, cur, frame, params, followed, matches);
			follow.cur_keypoints = cur.keypoints.size();
		}
		if (!follows_unmatched(params, metric))
			followed.clear();
	}
	const size_t n = matches.size();
	std::vector<PointPair> pairs;
	pairs.reserve(n);
	for (const auto &m : matches) {
		const auto p = static_cast<size_t>(m.prev);
		const auto c = static_cast<size_t>(m.cur);
		pairs.push_back({prev->keypoints[p].pt, cur.keypoints[c].pt, prev->colours[p], cur.colours[c]});
	}
	if (params.matching.subpixel && !prev->grey.empty() && !cur.grey.empty()) {
		StageTimer timer(result.timing, "subpixel");
		std::vector<cv::Point2f> from(n), to(n);
		for (size_t i = 0; i < n; ++i) {
			from[i] = pairs[i].prev;
			to[i] = pairs[i].cur;
		}
		refine_matches(*prev, cur, from, to, params.matching);
		for (size_t i = 0; i < n; ++i)
			pairs[i].cur = to[i];
	}
	// The person prior's regions in this frame: detected here, or the last detection's carried along by
	// the motion of the points inside them.
	std::vector<PriorRegion> people;
	std::vector<uint8_t> in_person(n, 0);
	std::vector<cv::Point2f> at; // the matches' positions in this frame, for the prior's regions
	if (params.prior.enabled) {
		if (cur.people) {
			people = *cur.people;
		} else if (prev_tracks != nullptr) {
			std::vector<cv::Point2f> from(n), to(n);
			for (size_t i = 0; i < n; ++i) {
				from[i] = pairs[i].prev;
				to[i] = pairs[i].cur;
			}
			people = carry_regions(prev_tracks->people, from, to, params.prior.max_age_frames);
		}
		at.resize(n);
		for (size_t i = 0; i < n; ++i)
			at[i] = pairs[i].cur;
		in_person = in_dynamic_category(at, people);
	}
	StageTimer timer(result.timing, "classify");
	// Points that take no part in the motion fits: those the motion memory knows move, and (seed 001) those
	// in the prior's dynamic category. Their labels are still decided by the tests.
	std::vector<uint8_t> known_moving = in_person;
	if (prev_tracks != nullptr) {
		for (size_t i = 0; i < n; ++i) {
			const auto p = static_cast<size_t>(matches[i].prev);
			if (p < prev_tracks->by_keypoint.size() &&
			    memory_says_moving(prev_tracks->by_keypoint[p], params.classifier, params.temporal))
				known_moving[i] = 1;
		}
	}
	Classification classification = classify(pairs, frame.left, params.classifier, known_moving);

	// Stereo: the camera's metric motion from the points that may vote, then seed 001's test per point.
	std::optional<PoseEstimate> pose;
	std::vector<cv::Point2f> predicted;
	std::vector<uint8_t> failed; // per match: the geometric test failed this frame
	const bool prev_has_depth = metric && prev->xyz.size() == prev->keypoints.size();
	if (prev_has_depth) {
		StageTimer pose_timer(result.timing, "pose");
		std::vector<cv::Vec3f> prev_xyz(n);
		std::vector<cv::Point2f> cur_px(n);
		std::vector<uint8_t> votes(n);
		for (size_t i = 0; i < n; ++i) {
			prev_xyz[i] = prev->xyz[static_cast<size_t>(matches[i].prev)];
			cur_px[i] = pairs[i].cur;
			votes[i] = known_moving[i] == 0 &&
				   !flagged_before(prev_tracks, static_cast<size_t>(matches[i].prev));
		}
		std::optional<MotionPrior> prior;
		if (prev_tracks != nullptr && prev_tracks->last_motion && prev_tracks->interval_ns > 0 &&
		    frame.device_ns > prev_tracks->t_ns) {
			prior = MotionPrior::constant_velocity(
				*prev_tracks->last_motion, static_cast<double>(prev_tracks->interval_ns) * 1e-9,
				static_cast<double>(frame.device_ns - prev_tracks->t_ns) * 1e-9, params.ego);
			prior->noise_px = prev_tracks->last_noise_px;
		}
		pose = estimate_pose(prev_xyz, cur_px, votes, *params.rig, params.ego, prior ? &*prior : nullptr);
		if (pose->valid) {
			double disparity_sigma = params.stereo.disparity_sigma_px;
			if (params.ego.measured_noise) {
				std::vector<float> cur_depth(n);
				for (size_t i = 0; i < n; ++i)
					cur_depth[i] = cur.xyz[static_cast<size_t>(matches[i].cur)][2];
				const double measured = measured_disparity_sigma(
					prev_xyz, cur_depth, pose->inlier_mask, pose->curr_from_prev, *params.rig,
					static_cast<size_t>(params.ego.min_inliers));
				if (measured > 0)
					disparity_sigma = std::max(measured, params.ego.min_disparity_sigma_px);
			}
			const GeometricContext context =
				GeometricContext::make(*params.rig, pose->curr_from_prev, disparity_sigma, params.ego,
						       pose->residual_sigma_px);
			predicted.assign(n, cv::Point2f(kNaN, kNaN));
			const bool have_texture = classification.texture_agrees.size() == n;
			failed.assign(n, 0);
			for (size_t i = 0; i < n; ++i) {
				const float cur_depth = cur.xyz[static_cast<size_t>(matches[i].cur)][2];
				const GeometricTest test =
					geometric_test(context, pairs[i].prev, prev_xyz[i], pairs[i].cur, cur_depth);
				predicted[i] = test.predicted;
				const bool has_prev_depth = std::isfinite(prev_xyz[i][2]);
				// Combined: a point the camera's translation hardly moves (parallax under
				// ego.min_parallax_px: far, or near the direction of travel) cannot tell the pose from
				// seed 000's homography, which is fitted to the whole scene at once and is the better
				// estimate there (a poorly determined translation would explain a mover's motion away).
				bool low_parallax = false;
				if (params.label_method == LabelMethod::Combined && has_prev_depth) {
					const cv::Vec3d p(prev_xyz[i][0], prev_xyz[i][1], prev_xyz[i][2]);
					const auto moved = params.rig->project(pose->curr_from_prev * p);
					const auto turned = params.rig->project(pose->curr_from_prev.r * p);
					low_parallax = params.ego.min_parallax_px > 0 && moved && turned &&
						       cv::norm(*moved - *turned) < params.ego.min_parallax_px;
				}
				PointLabel label =
					low_parallax ? classification.labels[i]
						     : combine(params.label_method, classification.labels[i], test,
							       has_prev_depth,
							       !have_texture || classification.texture_agrees[i] != 0);
				// Seed 000's double texture check (eqs. 6-7) with the pose's prediction: when what the
				// image now shows where a static point would be looks like the point, the match more
				// likely jumped to a look-alike (a repeated window) than the point moved.
				if (!low_parallax && label == PointLabel::Dynamic && std::isfinite(test.predicted.x) &&
				    test.predicted.x >= 0 && test.predicted.y >= 0 &&
				    test.predicted.x < static_cast<float>(frame.left.cols) &&
				    test.predicted.y < static_cast<float>(frame.left.rows) &&
				    texture_distance_near(pairs[i].prev_colour, frame.left, test.predicted,
							  params.classifier) <= params.classifier.texture_threshold)
					label = PointLabel::Uncertain;
				if (test.moving)
					failed[i] = 1;
				// Confirmed by a failure in the frame before that moved the same way: a mover's own
				// motion changes little between frames, a mismatch onto a look-alike jumps.
				const auto p = static_cast<size_t>(matches[i].prev);
				if (!low_parallax && label == PointLabel::Dynamic && params.ego.confirm_frames > 1 &&
				    (!flagged_before(prev_tracks, p) ||
				     !continues_motion(own_motion(pairs[i], test.predicted, classification.homography),
						       own_motion_before(prev_tracks, p), context.residual_var_px2,
						       params.ego.confirm_motion_change, params.ego.chi2_quantile)))
					label = PointLabel::Uncertain; // not yet confirmed
				classification.labels[i] = label;
			}
		}
	}

	if (params.prior.enabled && params.prior.rule == PriorLabelRule::Dynamic)
		for (size_t i = 0; i < n; ++i)
			if (in_person[i] != 0)
				classification.labels[i] = PointLabel::Dynamic;

	follow.matches = matches;
	follow.pairs = pairs;
	follow.homography = classification.homography ? &*classification.homography : nullptr;
	follow.texture_agrees = classification.texture_agrees;
	// With a metric pose the memory sums motion against the pose's prediction, which explains parallax.
	if (params.label_method != LabelMethod::Seed000)
		follow.predicted = predicted;
	TrackSet tracks = follow_tracks(prev_tracks, follow, params.classifier, params.temporal);
	// The prior's `weighted` rule: in a person region, the memory overturns `static` at its lower gate.
	const bool weighted = params.prior.enabled && params.prior.rule == PriorLabelRule::Weighted;
	promote_remembered_movers(classification.labels, matches, tracks, params.classifier, params.temporal,
				  weighted ? std::span<const uint8_t>(in_person) : std::span<const uint8_t>(),
				  params.prior.memory_chi2);
	if (params.prior.enabled && !people.empty()) {
		// Seed 001's potentially dynamic objects: judged point by point above, then as a whole.
		vote_potentially_dynamic(at, people, classification.labels, params.prior.object_vote);
	}
	// The camera in the world: chained on from the previous frame, or carried over when no pose was found.
	const geometry::Pose world_prev = prev_tracks != nullptr && prev_tracks->world_from_camera
						  ? *prev_tracks->world_from_camera
						  : geometry::Pose{};
	const bool moved = pose && pose->valid;
	geometry::Pose prev_from_curr = moved ? pose->curr_from_prev.inverse() : geometry::Pose{};
	geometry::Pose world_from_curr = world_prev * prev_from_curr;
	if (moved && params.ego.anchor_refine && params.ego.anchor_min_frames > 0 &&
	    params.label_method != LabelMethod::Seed000) {
		// The local refinement: the anchored static points in view, each where its track first put it in
		// the world, pull the chained pose back (refine_against_anchors). Only points nothing calls moving
		// and whose anchor has settled take part; the anchored test below then runs with the refined pose.
		StageTimer refine_timer(result.timing, "refine");
		std::vector<AnchorView> anchors;
		for (size_t i = 0; i < n; ++i) {
			const auto c = static_cast<size_t>(matches[i].cur);
			if (c >= tracks.by_keypoint.size())
				continue;
			const TrackState &state = tracks.by_keypoint[c];
			if (std::isnan(state.anchor_world[0]) ||
			    state.anchor_age < static_cast<uint32_t>(params.ego.anchor_min_frames) ||
			    classification.labels[i] == PointLabel::Dynamic || known_moving[i] != 0 ||
			    (i < failed.size() && failed[i] != 0) ||
			    flagged_before(prev_tracks, static_cast<size_t>(matches[i].prev)))
				continue;
			anchors.push_back({state.anchor_world, pairs[i].cur});
		}
		const AnchorRefinement refined =
			refine_against_anchors(anchors, world_from_curr, *params.rig, params.ego);
		if (refined.applied) {
			world_from_curr = refined.world_from_camera;
			prev_from_curr = world_prev.inverse() * world_from_curr;
		}
	}
	// Per match: made dynamic by the anchored test's finds beside it (for the output only, like a group's
	// label: a wrong spread cannot feed back into the pose or keep a track from being anchored).
	std::vector<uint8_t> spread;
	if (moved && params.ego.anchor_min_frames > 0 && params.label_method != LabelMethod::Seed000)
		spread = anchor_tracks(tracks, matches, cur, world_from_curr, classification, *params.rig, params,
				       *prev_tracks, failed);
	tracks.residual_by_keypoint.assign(cur.keypoints.size(), cv::Point2f(kNaN, kNaN));
	for (size_t i = 0; i < n; ++i)
		tracks.residual_by_keypoint[static_cast<size_t>(matches[i].cur)] =
			own_motion(pairs[i], i < predicted.size() ? predicted[i] : cv::Point2f(kNaN, kNaN),
				   classification.homography);
	std::vector<int> group_of_point;			  // per match: the published group it moves with, or -1
	double published_margin_px = params.groups.box_margin_px; // around the members in the published boxes
	// Seed 002's global flow, when the groups take their members from it.
	std::optional<CellFlow> cells;
	if (params.groups.enabled && params.dense.method != GroupFlow::Sparse && !prev->flow_image.empty() &&
	    !cur.flow_image.empty()) {
		StageTimer flow_timer(result.timing, "flow");
		cells = dense_flow(prev->flow_image, cur.flow_image, frame.left.size(), params.dense, workspace.dis);
	}
	if (params.groups.enabled) {
		StageTimer groups_timer(result.timing, "groups");
		// Each point's motion against what the static scene would do: the pose's prediction (stereo), else
		// the homography, else standing still.
		std::vector<MotionPoint> motion(n);
		const double frame_interval_s =
			prev_tracks != nullptr && frame.device_ns > prev_tracks->t_ns
				? static_cast<double>(frame.device_ns - prev_tracks->t_ns) * 1e-9
				: 0;
		for (size_t i = 0; i < n; ++i) {
			MotionPoint &m = motion[i];
			m.px = pairs[i].cur;
			m.flow = pairs[i].cur - pairs[i].prev;
			const auto c = static_cast<size_t>(matches[i].cur);
			const cv::Point2f own = tracks.residual_by_keypoint[c];
			if (moved && !(i < predicted.size() && std::isfinite(predicted[i].x)))
				// With a metric pose, a point without depth has no prediction: a homography cannot
				// explain the parallax of a camera moving through the scene, so it stays out of the
				// grouping.
				m.residual = cv::Point2f(kNaN, kNaN);
			else
				m.residual = std::isfinite(own.x) ? own : m.flow; // no scene model: standing still
			const auto p = static_cast<size_t>(matches[i].prev);
			m.octave = cur.keypoints[c].octave;
			if (!cells) // the aperture problem's mark (find_groups drops a group that slid along its edges)
				m.across =
					edge_across(*prev, pairs[i].prev, params.matching, params.dense.aperture_ratio);
			// The anchored test's spread counts too: it is output-only like the groups, and a mover walking
			// along the optical axis is found mostly by it (its image barely moves, its depth does, and
			// the anchored test confirms a point or two that the spread extends to its neighbours at
			// the same depth).
			m.dynamic = classification.labels[i] == PointLabel::Dynamic ||
				    (i < spread.size() && spread[i] != 0);
			if (c < cur.xyz.size() && std::isfinite(cur.xyz[c][2]))
				m.xyz = cur.xyz[c];
			if (p < prev->xyz.size() && std::isfinite(prev->xyz[p][2]))
				m.prev_xyz = prev->xyz[p];
			m.depth_on_edge = on_depth_edge(cur, c) || on_depth_edge(*prev, p);
			if (c < tracks.by_keypoint.size()) {
				const TrackState &track = tracks.by_keypoint[c];
				// The anchor is the mean of its first anchor_samples depths, one a frame: its time lies
				// half of them after the first.
				const double frames = static_cast<double>(track.anchor_age) -
						      0.5 * (static_cast<double>(track.anchor_samples) - 1);
				if (std::isfinite(track.anchor_world[0]) && frames > 0 && frame_interval_s > 0) {
					m.anchor_world = track.anchor_world;
					m.anchor_span_s = frames * frame_interval_s;
				}
			}
		}
		// The followed points after the matched ones: clustered, never labelled or published.
		for (const FollowedPoint &f : followed) {
			const auto p = static_cast<size_t>(f.prev);
			MotionPoint m;
			m.px = f.at;
			m.flow = f.at - prev->keypoints[p].pt;
			const cv::Point2f own = own_motion({prev->keypoints[p].pt, f.at, {}, {}},
							   cv::Point2f(kNaN, kNaN), classification.homography);
			m.residual = std::isfinite(own.x) ? own : m.flow; // no scene model: standing still
			m.octave = prev->keypoints[p].octave;
			m.across = f.across;
			motion.push_back(m);
		}
		GroupMotionContext context;
		context.dt_s = frame_interval_s;
		if (moved) {
			context.curr_from_prev = pose->curr_from_prev;
			context.world_from_curr = world_from_curr;
		}
		context.rig = params.rig;
		context.image_size = frame.left.size();
		GroupParams group_params = params.groups;
		if (group_params.members == GroupMembers::Auto)
			group_params.members = moved ? GroupMembers::Labels : GroupMembers::Flow;
		const GroupMemory *memory = prev_tracks != nullptr ? &prev_tracks->groups : nullptr;
		GroupOutput found;
		if (cells) {
			// Seed 002's global flow: the grid's cells are the members (split by the mean residual), and
			// the feature points inside a group's box that move with it join it.
			StaticSceneModel model;
			model.homography = classification.homography;
			if (moved)
				model.curr_from_prev = pose->curr_from_prev;
			model.rig = params.rig;
			const std::vector<MotionPoint> cell_points =
				cell_motion(*cells, params.dense, prev->cell_depth, cur.cell_depth, model);
			group_params.members = GroupMembers::Flow;
			group_params.box_margin_px = 0.5 * params.dense.step_px;
			published_margin_px = group_params.box_margin_px;
			group_params.member_area_px2 = static_cast<double>(params.dense.step_px) * params.dense.step_px;
			group_params.min_points = std::max(group_params.min_points, params.dense.min_cells);
			const std::vector<uint32_t> strong =
				supported_cells(strong_motion(cell_points, group_params), cells->cols, cells->rows,
						params.dense.min_strong_neighbours);
			found = find_groups(cell_points, memory, context, group_params, workspace.affinity, &strong);
			const std::vector<int> group_of_cell = std::move(found.group_of_point);
			found.group_of_point.assign(n, -1);
			join_groups(motion, found, group_params, found.group_of_point);
			if (params.dense.label_cells)
				join_by_cells(motion, group_of_cell, cells->cols, cells->rows, params.dense.step_px,
					      0.5 * group_params.min_flow_px, found.group_of_point);
		} else {
			found = find_groups(motion, memory, context, group_params, workspace.affinity);
		}
		// Inside "groups", reported on its own: the clustering's cost is what groups.max_points bounds.
		if (found.clustering_ms)
			result.timing.push_back({"clustering", *found.clustering_ms});
		group_of_point = std::move(found.group_of_point);
		group_of_point.resize(n); // the followed points are not frame points
		tracks.groups = std::move(found.memory);
		result.groups = std::move(found.groups);
		if (params.prior.enabled) {
			// A group is a person when most of its points lie in the prior's person regions.
			std::vector<int> members(result.groups.size(), 0), on_person(result.groups.size(), 0);
			for (size_t i = 0; i < n; ++i) {
				const int g = group_of_point[i];
				if (g < 0 || static_cast<size_t>(g) >= result.groups.size())
					continue;
				++members[static_cast<size_t>(g)];
				on_person[static_cast<size_t>(g)] += in_person[i];
			}
			for (size_t g = 0; g < result.groups.size(); ++g)
				result.groups[g].class_name =
					members[g] > 0 && 2 * on_person[g] > members[g] ? "person" : "unknown";
		}
	}
	tracks.people = std::move(people);
	publish_people(tracks.people, result);
	tracks.dynamic_by_keypoint.assign(cur.keypoints.size(), 0);
	for (size_t i = 0; i < n; ++i)
		if (classification.labels[i] == PointLabel::Dynamic || (i < failed.size() && failed[i] != 0))
			tracks.dynamic_by_keypoint[static_cast<size_t>(matches[i].cur)] = 1;
	result.points.reserve(n);
	tracks.published_dynamic_by_keypoint.assign(cur.keypoints.size(), 0);
	// Per match: new to the tracks and on a group that shows new corners (new_corners_of_groups).
	std::vector<uint8_t> new_on_group;
	if (params.groups.label_points && params.groups.new_in_box_frames > 0 && !result.groups.empty()) {
		at.resize(n); // the matches' positions, as for the prior's regions
		std::vector<uint32_t> age(n);
		std::vector<float> depth(n, std::numeric_limits<float>::quiet_NaN());
		std::vector<uint8_t> dynamic(n);
		for (size_t i = 0; i < n; ++i) {
			const auto c = static_cast<size_t>(matches[i].cur);
			at[i] = pairs[i].cur;
			age[i] = tracks.by_keypoint[c].age;
			if (c < cur.xyz.size())
				depth[i] = cur.xyz[c][2];
			dynamic[i] = classification.labels[i] == PointLabel::Dynamic ||
				     (i < group_of_point.size() && group_of_point[i] >= 0);
		}
		new_on_group = new_corners_of_groups(at, age, depth, dynamic, result.groups, published_margin_px,
						     params.groups);
	}
	for (size_t i = 0; i < n; ++i) {
		LabelledPoint point;
		point.u = pairs[i].cur.x;
		point.v = pairs[i].cur.y;
		point.prev_u = pairs[i].prev.x;
		point.prev_v = pairs[i].prev.y;
		point.label = classification.labels[i];
		// A group's label and the anchored test's spread are for the output only: they do not keep points
		// from voting for the next pose or confirm them, so a group or a spread that wrongly covers static
		// points cannot feed back into the pose.
		const bool in_group = params.groups.label_points && i < group_of_point.size() && group_of_point[i] >= 0;
		if (in_group || (i < spread.size() && spread[i] != 0))
			point.label = PointLabel::Dynamic;
		const auto c = static_cast<size_t>(matches[i].cur);
		const auto p = static_cast<size_t>(matches[i].prev);
		if (point.label != PointLabel::Dynamic && params.groups.label_points &&
		    params.groups.keep_labels_in_box && prev_tracks != nullptr &&
		    p < prev_tracks->published_dynamic_by_keypoint.size() &&
		    prev_tracks->published_dynamic_by_keypoint[p] != 0 && inside_a_box(pairs[i].cur, result.groups))
			point.label = PointLabel::Dynamic;
		if (i < new_on_group.size() && new_on_group[i] != 0)
			point.label = PointLabel::Dynamic;
		tracks.published_dynamic_by_keypoint[c] = point.label == PointLabel::Dynamic ? 1 : 0;
		point.track = tracks.by_keypoint[c].id;
		point.in_person = in_person[i] != 0;
		if (c < cur.xyz.size() && std::isfinite(cur.xyz[c][2]))
			point.xyz_m = std::array<float, 3>{cur.xyz[c][0], cur.xyz[c][1], cur.xyz[c][2]};
		result.points.push_back(point);
	}

	EgoMotion ego;
	if (classification.homography) {
		std::array<double, 9> h{};
		for (int r = 0; r < 3; ++r)
			for (int c = 0; c < 3; ++c)
				h[static_cast<size_t>(r * 3 + c)] = (*classification.homography)(r, c);
		ego.homography = h;
		ego.homography_inliers = classification.homography_inliers;
		ego.homography_refined = classification.homography_refined;
		ego.inliers = classification.homography_inliers;
	}
	if (metric) {
		// Without an estimate the camera is taken to stand where it was (world_from_curr = world_prev).
		tracks.world_from_camera = world_from_curr;
		ego.valid = moved;
		if (moved) {
			tracks.last_motion = pose->curr_from_prev;
			tracks.last_noise_px = pose->residual_sigma_px;
			ego.inliers = pose->inliers;
		} else {
			ego.reason = pose ? pose->reason : "the previous frame has no depth";
		}
		fill_pose(ego, moved ? &prev_from_curr : nullptr, world_from_curr);
		if (params.keyframes.enabled) {
			tracks.last_keyframe = prev_tracks->last_keyframe;
			ego.keyframe = false;
			if (moved && tracks.last_keyframe) {
				const std::vector<StaticObservation> observed = static_observations(result.points);
				const KeyframeDecision decision =
					decide_keyframe(*tracks.last_keyframe, world_from_curr, observed, *params.rig,
							params.keyframes);
				ego.covisibility = decision.covisibility;
				ego.keyframe = decision.keyframe;
				if (decision.keyframe)
					tracks.last_keyframe = make_keyframe(frame.sequence, world_from_curr, observed);
			}
		}
	}
	if (classification.homography || metric)
		result.ego = ego;
	return tracks;
}

} // namespace stereod::vision
