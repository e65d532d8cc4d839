#include "core/vision/groups.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "core/clock.hpp"
#include "core/vision/stereo.hpp"

namespace stereod::vision {
namespace {

float percentile_of(std::vector<float> &v, double q)
{
	const auto at = v.begin() + static_cast<std::ptrdiff_t>(std::lround(q * static_cast<double>(v.size() - 1)));
	std::nth_element(v.begin(), at, v.end());
	return *at;
}

std::array<double, 3> array_of(const cv::Vec3d &v)
{
	return {v[0], v[1], v[2]};
}

/// A velocity per axis and the variance of each.
struct Estimate3 {
	cv::Vec3d value, variance;
};

/// One cluster's measurements before tracking.
struct Cluster {
	std::vector<uint32_t> members; ///< point indices
	cv::Rect2f box;
	cv::Point2f centre;
	cv::Point2f flow;     ///< median observed flow, pixels per frame
	cv::Point2f residual; ///< median residual
	std::optional<cv::Vec3d> position, extent, velocity, world_velocity;
	/// The members' median world velocity since their anchors (MotionPoint::anchor_world), where enough have
	/// one, and that median's variance per axis (pi / 2 times the members' sample variance over their number).
	std::optional<Estimate3> anchored_velocity;
};

/// A member's anchor must lie at least this far back to measure its velocity by (a third of a second).
constexpr double kMinAnchorSpanS = 0.33;

Cluster measure(std::vector<uint32_t> members, const std::vector<MotionPoint> &points,
		const GroupMotionContext &context, float margin)
{
	Cluster c;
	c.members = std::move(members);
	std::vector<float> u, v, fu, fv, ru, rv;
	float u0 = 1e9f, v0 = 1e9f, u1 = -1e9f, v1 = -1e9f;
	std::array<std::vector<float>, 3> xyz, rel, world, anchored;
	for (const uint32_t i : c.members) {
		const MotionPoint &p = points[i];
		u0 = std::min(u0, p.px.x);
		v0 = std::min(v0, p.px.y);
		u1 = std::max(u1, p.px.x);
		v1 = std::max(v1, p.px.y);
		u.push_back(p.px.x);
		v.push_back(p.px.y);
		fu.push_back(p.flow.x);
		fv.push_back(p.flow.y);
		ru.push_back(p.residual.x);
		rv.push_back(p.residual.y);
		if (!p.xyz)
			continue;
		for (int a = 0; a < 3; ++a)
			xyz[static_cast<size_t>(a)].push_back((*p.xyz)[a]);
	}
	// The velocities from the members whose depths came from windows on one surface, where enough have both:
	// a window across the mover's outline follows its depth only in part, and on a mover along the line of
	// sight such members held the median velocity at half the true one (docs/groups.md, stop 50).
	constexpr size_t kMinWithDepth = 3;
	const auto clean = std::count_if(c.members.begin(), c.members.end(), [&](uint32_t i) {
		return points[i].xyz && points[i].prev_xyz && !points[i].depth_on_edge;
	});
	const bool clean_only = static_cast<size_t>(clean) >= kMinWithDepth;
	for (const uint32_t i : c.members) {
		const MotionPoint &p = points[i];
		if (!p.xyz || (clean_only && p.depth_on_edge))
			continue;
		if (p.anchor_world && p.anchor_span_s >= kMinAnchorSpanS && context.world_from_curr) {
			const cv::Vec3d since =
				(*context.world_from_curr * cv::Vec3d(*p.xyz) - cv::Vec3d(*p.anchor_world)) /
				p.anchor_span_s;
			for (int a = 0; a < 3; ++a)
				anchored[static_cast<size_t>(a)].push_back(static_cast<float>(since[a]));
		}
		if (p.prev_xyz && context.dt_s > 0) {
			const cv::Vec3d now(*p.xyz), before(*p.prev_xyz);
			const cv::Vec3d relative = (now - before) / context.dt_s;
			for (int a = 0; a < 3; ++a)
				rel[static_cast<size_t>(a)].push_back(static_cast<float>(relative[a]));
			if (context.curr_from_prev && context.world_from_curr) {
				// Where a static point seen at `before` would be now; the difference is the point's own
				// motion.
				const cv::Vec3d moved = ((now - *context.curr_from_prev * before) / context.dt_s);
				const cv::Vec3d in_world = context.world_from_curr->r * moved;
				for (int a = 0; a < 3; ++a)
					world[static_cast<size_t>(a)].push_back(static_cast<float>(in_world[a]));
			}
		}
	}
	c.box = cv::Rect2f(u0 - margin, v0 - margin, u1 - u0 + 2 * margin, v1 - v0 + 2 * margin);
	c.centre = {median_of(u), median_of(v)};
	c.flow = {median_of(fu), median_of(fv)};
	c.residual = {median_of(ru), median_of(rv)};
	if (xyz[0].size() >= kMinWithDepth) {
		cv::Vec3d position, extent;
		for (size_t a = 0; a < 3; ++a) {
			position[static_cast<int>(a)] = median_of(xyz[a]);
			extent[static_cast<int>(a)] = percentile_of(xyz[a], 0.9) - percentile_of(xyz[a], 0.1);
		}
		c.position = position;
		c.extent = extent;
	}
	if (rel[0].size() >= kMinWithDepth)
		c.velocity = cv::Vec3d(median_of(rel[0]), median_of(rel[1]), median_of(rel[2]));
	if (world[0].size() >= kMinWithDepth)
		c.world_velocity = cv::Vec3d(median_of(world[0]), median_of(world[1]), median_of(world[2]));
	if (anchored[0].size() >= kMinWithDepth) {
		Estimate3 e;
		for (size_t a = 0; a < 3; ++a) {
			const auto &values = anchored[a];
			double mean = 0, squares = 0;
			for (const float x : values)
				mean += x;
			mean /= static_cast<double>(values.size());
			for (const float x : values)
				squares += (x - mean) * (x - mean);
			e.value[static_cast<int>(a)] = median_of(values);
			e.variance[static_cast<int>(a)] = std::numbers::pi / 2 * squares /
							  static_cast<double>(values.size() - 1) /
							  static_cast<double>(values.size());
		}
		c.anchored_velocity = e;
	}
	return c;
}

template <typename T>
T blend(const std::optional<T> &old, const T &now, double weight)
{
	return old ? T(*old * (1 - weight) + now * weight) : now;
}

/// The box around the members' positions.
cv::Rect2f extent_of(const std::vector<uint32_t> &members, const std::vector<MotionPoint> &points)
{
	float u0 = 1e9f, v0 = 1e9f, u1 = -1e9f, v1 = -1e9f;
	for (const uint32_t i : members) {
		u0 = std::min(u0, points[i].px.x);
		v0 = std::min(v0, points[i].px.y);
		u1 = std::max(u1, points[i].px.x);
		v1 = std::max(v1, points[i].px.y);
	}
	return {u0, v0, u1 - u0, v1 - v0};
}

/// A group not found in this frame as published: where it was last published, moved on by its image
/// velocity and (camera-frame) velocity for the frames it has been missed; no members of its own.
TargetGroup coasted(const TrackedGroup &track, double dt_s, cv::Size image)
{
	TargetGroup g = *track.published;
	const double elapsed = dt_s * track.missed_frames;
	const auto du = static_cast<float>(track.image_velocity_pxps.x * elapsed);
	const auto dv = static_cast<float>(track.image_velocity_pxps.y * elapsed);
	g.box_px = {g.box_px[0] + du, g.box_px[1] + dv, g.box_px[2] + du, g.box_px[3] + dv};
	if (!image.empty()) { // the part still in view: box_px is in the left image
		const auto w = static_cast<float>(image.width), h = static_cast<float>(image.height);
		g.box_px = {std::clamp(g.box_px[0], 0.F, w), std::clamp(g.box_px[1], 0.F, h),
			    std::clamp(g.box_px[2], 0.F, w), std::clamp(g.box_px[3], 0.F, h)};
	}
	if (g.position_m && g.velocity_mps)
		for (size_t k = 0; k < 3; ++k)
			(*g.position_m)[k] += (*g.velocity_mps)[k] * elapsed;
	g.point_count = 0; // age_frames stays: the frames it was found in
	g.missed_frames = track.missed_frames;
	return g;
}

/// Whether a group's predicted `box`, moving `step` pixels a frame, leaves an `image` of that size sideways
/// through the band along its left or right edge (band_px wide) where feature points give out: it lies in the
/// band, at least half of it still in the image, and crosses the band within `frames`. Only sideways: a near mover's
/// feet lie in the bottom band whenever it stands close, and movers stay on the ground.
bool leaves_through_edge(const cv::Rect2f &box, cv::Point2f step, cv::Size image, double band_px, int frames)
{
	const float centre = box.x + 0.5F * box.width;
	if (image.empty() || frames <= 0 || centre < 0 || centre > static_cast<float>(image.width))
		return false;
	const auto band = static_cast<float>(band_px);
	const bool fast_enough = std::abs(step.x) * static_cast<float>(frames) >= band;
	return fast_enough &&
	       ((step.x < 0 && box.x < band) || (step.x > 0 && box.br().x > static_cast<float>(image.width) - band));
}

/// Whether a track's predicted box lies behind a box found in this frame: at least half of it inside that box,
/// and the other nearer the camera by more than `same_depth_ratio` of the nearer depth (at one depth it is as
/// likely a piece of the same mover). Without both depths, no: on monocular footage the box's bottom edge
/// (the nearer mover's feet lower in the image) was tried and took a walker's own track from it on vtest when
/// its residual swung from one frame to the next (docs/groups.md, stop 49).
bool hidden_behind(const cv::Rect2f &predicted, std::optional<double> depth, const cv::Rect2f &box,
		   std::optional<double> box_depth, double same_depth_ratio)
{
	const float area = predicted.area();
	if (!depth || !box_depth || area <= 0 || (predicted & box).area() < 0.5F * area)
		return false;
	return *depth - *box_depth > same_depth_ratio * *box_depth;
}

/// The groups' own tolerance: the dense flow's cells' or the feature points' (GroupParams).
double member_tolerance(const GroupParams &params)
{
	return params.member_area_px2 > 0 ? params.member_tolerance_px : params.point_tolerance_px;
}

/// The rule a point's residual r moves with a group's g by (join_groups, with label_tolerance_px; a cluster's
/// members, with member_tolerance): |r - g| <= max(tolerance, |g| / 2)
/// and |r - g| < |r|, nearer the group's motion than standing still. NaN residuals never do.
bool moves_with(cv::Point2f r, cv::Point2f g, double tolerance_px)
{
	const double off = cv::norm(r - g);
	return off <= std::max(tolerance_px, 0.5 * cv::norm(g)) && off < cv::norm(r);
}

/// The join rule's bound on what is left of two motions' difference: max(tolerance, half the stronger).
bool differ_alike(cv::Point2f left, cv::Point2f a, cv::Point2f b, const GroupParams &params)
{
	const double strength = std::max(cv::norm(a), cv::norm(b));
	return cv::norm(left) <= std::max(member_tolerance(params), 0.5 * strength);
}

/// The rule two motions a and b (clusters' or tracks' median residuals) are alike by: |a - b| <=
/// max(tolerance, half the stronger), the join rule without a side taken.
bool move_alike(cv::Point2f a, cv::Point2f b, const GroupParams &params)
{
	return differ_alike(a - b, a, b, params);
}

/// move_alike, allowing for one mover's image spreading out or drawing in (GroupParams::merge_looming):
/// the residuals of its pieces at `pa` and `pb` (at one depth) differ by k (pa - pb) for a scale k the
/// bound allows, and by what move_alike allows beyond that.
bool move_alike_looming(cv::Point2f ra, cv::Point2f rb, cv::Point2f pa, cv::Point2f pb, const GroupParams &params)
{
	if (move_alike(ra, rb, params))
		return true;
	const cv::Point2f gap = pa - pb, differ = ra - rb;
	// Only pieces above one another: movers stand on the ground, so two at one depth are side by side,
	// and there spreading out cannot be told from two movers going apart.
	if (params.merge_looming <= 0 || std::abs(gap.y) < std::max(std::abs(gap.x), 1.0F))
		return false;
	const double k = std::clamp(static_cast<double>(differ.y) / gap.y, -params.merge_looming, params.merge_looming);
	return differ_alike(differ - static_cast<float>(k) * gap, ra, rb, params);
}

/// The median, axis by axis, of one of the members' points: their residuals or their positions.
cv::Point2f median_point(const std::vector<uint32_t> &members, const std::vector<MotionPoint> &points,
			 cv::Point2f MotionPoint::*which)
{
	std::vector<float> u, v;
	for (const uint32_t i : members) {
		u.push_back((points[i].*which).x);
		v.push_back((points[i].*which).y);
	}
	return {median_of(u), median_of(v)};
}

/// The share of its box a cluster of grid cells covers (each member stands for member_area_px2).
double box_fill(const std::vector<uint32_t> &members, const std::vector<MotionPoint> &points, const GroupParams &params)
{
	const cv::Rect2f e = extent_of(members, points);
	const double side = std::sqrt(params.member_area_px2); // the box around the cells' centres
	return static_cast<double>(members.size()) * params.member_area_px2 / ((e.width + side) * (e.height + side));
}

/// Whether two depths are one, within `ratio` of the nearer (GroupParams::split_same_depth).
bool at_one_depth(float za, float zb, double ratio)
{
	return std::abs(za - zb) <= ratio * std::min(za, zb);
}

/// A cluster of grid cells cut into its connected regions: cells (at their positions in this frame, `step`
/// apart on the grid) within gap_cells + 1 cells of each other in both directions are connected. Affinity
/// Propagation with seed 002's preference makes few clusters, and two people walking alike far apart land
/// in one; a mover is one region.
std::vector<std::vector<uint32_t>> connected_parts(const std::vector<uint32_t> &members,
						   const std::vector<MotionPoint> &points, double reach,
						   double same_depth_ratio)
{
	std::vector<uint32_t> parent(members.size());
	for (size_t i = 0; i < parent.size(); ++i)
		parent[i] = static_cast<uint32_t>(i);
	const auto root = [&parent](uint32_t i) {
		while (parent[i] != i)
			i = parent[i] = parent[parent[i]];
		return i;
	};
	for (size_t a = 0; a < members.size(); ++a)
		for (size_t b = a + 1; b < members.size(); ++b) {
			const cv::Point2f d = points[members[a]].px - points[members[b]].px;
			if (std::abs(d.x) <= reach && std::abs(d.y) <= reach)
				parent[root(static_cast<uint32_t>(a))] = root(static_cast<uint32_t>(b));
		}
	// With depth, regions at the same depth (within same_depth_ratio of the nearer) stay one: a weakly
	// textured mover shows motion only at its textured spots, all at its depth, where two walkers apart
	// are rarely at the same distance. Without depth (monocular) the regions stay apart.
	if (same_depth_ratio > 0) {
		std::vector<std::vector<float>> depths(members.size());
		for (size_t i = 0; i < members.size(); ++i)
			if (const auto &xyz = points[members[i]].xyz; xyz && (*xyz)[2] > 0)
				depths[root(static_cast<uint32_t>(i))].push_back((*xyz)[2]);
		std::vector<std::pair<uint32_t, float>> region_depth;
		for (size_t r = 0; r < members.size(); ++r)
			if (depths[r].size() >= 3)
				region_depth.emplace_back(static_cast<uint32_t>(r), median_of(depths[r]));
		for (size_t a = 0; a < region_depth.size(); ++a)
			for (size_t b = a + 1; b < region_depth.size(); ++b) {
				if (at_one_depth(region_depth[a].second, region_depth[b].second, same_depth_ratio))
					parent[root(region_depth[a].first)] = root(region_depth[b].first);
			}
	}
	std::vector<std::vector<uint32_t>> parts;
	std::vector<int> part_of_root(members.size(), -1);
	for (size_t i = 0; i < members.size(); ++i) {
		const uint32_t r = root(static_cast<uint32_t>(i));
		if (part_of_root[r] < 0) {
			part_of_root[r] = static_cast<int>(parts.size());
			parts.emplace_back();
		}
		parts[static_cast<size_t>(part_of_root[r])].push_back(members[i]);
	}
	return parts;
}

/// The median depth of the members that have one; nullopt with fewer than three.
std::optional<float> median_depth(const std::vector<uint32_t> &members, const std::vector<MotionPoint> &points)
{
	std::vector<float> depths;
	for (const uint32_t i : members)
		if (const auto &xyz = points[i].xyz; xyz && (*xyz)[2] > 0)
			depths.push_back(static_cast<float>((*xyz)[2]));
	if (depths.size() < 3)
		return std::nullopt;
	return median_of(depths);
}

/// Clusters that move alike (the join rule on their median residuals) are one when their boxes touch
/// (within merge_gap_px), or, with depth, when their median depths agree within split_same_depth of the
/// nearer and the gap between their boxes is no wider than the larger box's longer side (the dense flow's
/// cells) or merge_reach_m at that depth (feature points; `fx` is the rig's focal length, 0 without a rig).
/// Affinity Propagation over many samples, whose exemplars only reach their k nearest, cuts a large mover
/// into pieces; a weakly textured one shows its motion at a few spots apart, all at one depth (the rule
/// connected_parts applies inside a cluster), where two movers side by side are rarely at one distance.
void merge_alike(std::vector<std::vector<uint32_t>> &clusters, const std::vector<MotionPoint> &points,
		 const GroupParams &params, double fx)
{
	// Each cluster's extent, motion and depth, measured once and again only for a merged one.
	const bool cells = params.member_area_px2 > 0;
	const bool with_depth = params.split_same_depth > 0 && (cells || (params.merge_reach_m > 0 && fx > 0));
	std::vector<cv::Rect2f> extents;
	std::vector<cv::Point2f> motion, centre;
	std::vector<std::optional<float>> depth;
	const auto measure_cluster = [&](size_t c) {
		extents[c] = extent_of(clusters[c], points);
		motion[c] = median_point(clusters[c], points, &MotionPoint::residual);
		centre[c] = median_point(clusters[c], points, &MotionPoint::px);
		depth[c] = with_depth ? median_depth(clusters[c], points) : std::nullopt;
	};
	extents.resize(clusters.size());
	motion.resize(clusters.size());
	centre.resize(clusters.size());
	depth.resize(clusters.size());
	for (size_t c = 0; c < clusters.size(); ++c)
		measure_cluster(c);
	const auto grown = [](const cv::Rect2f &r, double by) {
		const auto g = static_cast<float>(by);
		return cv::Rect2f(r.x - g, r.y - g, r.width + 2 * g, r.height + 2 * g);
	};
	bool merged = true;
	while (merged && clusters.size() > 1) {
		merged = false;
		for (size_t a = 0; a < clusters.size() && !merged; ++a)
			for (size_t b = a + 1; b < clusters.size() && !merged; ++b) {
				const bool same_depth = depth[a] && depth[b] &&
							at_one_depth(*depth[a], *depth[b], params.split_same_depth);
				// At one depth the pieces may be one mover's spreading out as it comes closer.
				if (same_depth ? !move_alike_looming(motion[a], motion[b], centre[a], centre[b], params)
					       : !move_alike(motion[a], motion[b], params))
					continue;
				const double touch = params.box_margin_px + 0.5 * params.merge_gap_px;
				bool join = params.merge_gap_px >= 0 &&
					    (grown(extents[a], touch) & grown(extents[b], touch)).area() > 0;
				if (!join && same_depth) {
					// How far apart the pieces may lie: the grid's, the larger piece's longer side
					// (stop 29); the feature points', merge_reach_m at the nearer depth.
					const double reach =
						cells ? std::max({extents[a].width, extents[a].height, extents[b].width,
								  extents[b].height}) +
								2 * params.box_margin_px
						      : params.merge_reach_m * fx / std::min(*depth[a], *depth[b]);
					join = (grown(extents[a], 0.5 * reach) & grown(extents[b], 0.5 * reach))
						       .area() > 0;
				}
				if (join) {
					clusters[a].insert(clusters[a].end(), clusters[b].begin(), clusters[b].end());
					const auto at = static_cast<std::ptrdiff_t>(b);
					clusters.erase(clusters.begin() + at);
					extents.erase(extents.begin() + at);
					motion.erase(motion.begin() + at);
					centre.erase(centre.begin() + at);
					depth.erase(depth.begin() + at);
					measure_cluster(a);
					merged = true;
				}
			}
	}
}

} // namespace

std::vector<uint32_t> strong_motion(const std::vector<MotionPoint> &points, const GroupParams &params)
{
	std::vector<uint32_t> strong;
	if (points.empty())
		return strong;
	if (params.members == GroupMembers::Labels) {
		for (size_t i = 0; i < points.size(); ++i)
			if (points[i].dynamic && std::isfinite(points[i].residual.x) &&
			    std::isfinite(points[i].residual.y))
				strong.push_back(static_cast<uint32_t>(i));
		return strong;
	}
	double mean_u = 0, mean_v = 0;
	size_t measured = 0; // a point without a prediction has a NaN residual and takes no part
	for (const auto &p : points)
		if (std::isfinite(p.residual.x) && std::isfinite(p.residual.y)) {
			mean_u += std::abs(p.residual.x);
			mean_v += std::abs(p.residual.y);
			++measured;
		}
	if (measured == 0)
		return strong;
	mean_u /= static_cast<double>(measured);
	mean_v /= static_cast<double>(measured);
	for (size_t i = 0; i < points.size(); ++i) {
		const cv::Point2f r = points[i].residual;
		if ((std::abs(r.x) > mean_u || std::abs(r.y) > mean_v) && std::hypot(r.x, r.y) >= params.min_flow_px)
			strong.push_back(static_cast<uint32_t>(i));
	}
	return strong;
}

void join_groups(const std::vector<MotionPoint> &points, const GroupOutput &found, const GroupParams &params,
		 std::vector<int> &group_of_point)
{
	for (size_t g = 0; g < found.groups.size() && g < found.residuals.size(); ++g) {
		const cv::Point2f group_residual = found.residuals[g];
		const double strength = cv::norm(group_residual);
		if (strength < params.min_flow_px)
			continue;
		const auto &b = found.groups[g].box_px;
		// Feature points join inside their group's members' extent, not its published box: the margin
		// covers the mover's body beyond its corners, but a point in that band that moves the mover's way
		// is as often a corner of its outline on the background beside it (on the sim, joining in the
		// margin cost the labels' precision 0.005-0.025). A grid's cells cover their margin.
		const double in = params.member_area_px2 > 0 ? 0.0 : params.box_margin_px;
		for (size_t i = 0; i < points.size() && i < group_of_point.size(); ++i) {
			const MotionPoint &p = points[i];
			if (group_of_point[i] < 0 && p.px.x >= b[0] + in && p.px.x <= b[2] - in &&
			    p.px.y >= b[1] + in && p.px.y <= b[3] - in &&
			    moves_with(p.residual, group_residual, params.label_tolerance_px))
				group_of_point[i] = static_cast<int>(g);
		}
	}
}

bool box_holds(const TargetGroup &group, cv::Point2f at)
{
	const auto &b = group.box_px;
	return at.x >= b[0] && at.y >= b[1] && at.x <= b[2] && at.y <= b[3];
}

std::vector<uint8_t> boxes_renewing_corners(std::span<const cv::Point2f> at, std::span<const uint32_t> age,
					    std::span<const uint8_t> dynamic, const std::vector<TargetGroup> &groups,
					    uint32_t young_frames, size_t min_points)
{
	std::vector<uint8_t> renewing(groups.size(), 0);
	std::vector<size_t> inside(groups.size(), 0), young_inside(groups.size(), 0);
	size_t outside = 0, young_outside = 0;
	const size_t n = std::min({at.size(), age.size(), dynamic.size()});
	for (size_t i = 0; i < n; ++i) {
		const bool young = age[i] <= young_frames;
		bool in_any = false;
		for (size_t g = 0; g < groups.size(); ++g) {
			if (!box_holds(groups[g], at[i]))
				continue;
			in_any = true;
			++inside[g];
			young_inside[g] += young ? 1 : 0;
		}
		if (!in_any && dynamic[i] == 0) {
			++outside;
			young_outside += young ? 1 : 0;
		}
	}
	if (outside == 0)
		return renewing;
	for (size_t g = 0; g < groups.size(); ++g)
		// young_inside / inside >= 2 young_outside / outside, without the divisions.
		renewing[g] = inside[g] >= std::max<size_t>(min_points, 1) &&
			      young_inside[g] * outside >= 2 * young_outside * inside[g] && young_inside[g] > 0;
	return renewing;
}

std::vector<uint8_t> new_corners_of_groups(std::span<const cv::Point2f> at, std::span<const uint32_t> age,
					   std::span<const float> depth_m, std::span<const uint8_t> dynamic,
					   const std::vector<TargetGroup> &groups, double margin_px,
					   const GroupParams &params)
{
	const size_t n = std::min({at.size(), age.size(), depth_m.size(), dynamic.size()});
	std::vector<uint8_t> found(n, 0);
	if (params.new_in_box_frames <= 0)
		return found;
	const auto young_frames = static_cast<uint32_t>(params.new_in_box_frames);
	const std::vector<uint8_t> renewing =
		boxes_renewing_corners(at, age, dynamic, groups, young_frames, static_cast<size_t>(params.min_points));
	for (size_t i = 0; i < n; ++i) {
		if (dynamic[i] != 0 || age[i] > young_frames)
			continue;
		for (size_t g = 0; g < groups.size(); ++g) {
			const auto &b = groups[g].box_px;
			// The members' extent (the box without its margin), as feature points join a group by
			// (join_groups): a new point in the margin is as often the background's at the outline.
			const double x0 = b[0] + margin_px, y0 = b[1] + margin_px, x1 = b[2] - margin_px,
				     y1 = b[3] - margin_px;
			const double bottom = y1 + params.new_below_box_share * (y1 - y0);
			if (renewing[g] == 0 || at[i].x < x0 || at[i].x > x1 || at[i].y < y0 || at[i].y > bottom)
				continue;
			if (std::isfinite(depth_m[i]) && groups[g].position_m &&
			    !at_one_depth(depth_m[i], static_cast<float>((*groups[g].position_m)[2]),
					  params.split_same_depth))
				continue;
			found[i] = 1;
			break;
		}
	}
	return found;
}

namespace {

/// On an edge (`across` set), with a residual across it under `min_flow_px`: whatever the point's whole
/// residual, the part the flow measured says it stands still.
bool slides_along_edge(const MotionPoint &p, double min_flow_px)
{
	return (p.across.x != 0 || p.across.y != 0) && std::abs(p.residual.dot(p.across)) < min_flow_px;
}

/// The fewest points a cluster needs to be a group (min_points, at least 1).
size_t min_group_points(const GroupParams &params)
{
	return static_cast<size_t>(std::max(1, params.min_points));
}

/// What one round of clustering reports.
struct ClusterRound {
	int clusters = 0;
	int iterations = 0;
	double preference = 0;	  ///< Affinity Propagation's, as used
	double clustering_ms = 0; ///< Affinity Propagation's own time
};

/// One round of clustering over the points `chosen`: seed 002's samples, Affinity Propagation, clusters
/// under min_points dropped, members that do not move like their cluster's median taken out, and a grid's
/// cells cut into connected regions. The clusters left are appended to `kept`; the points in none of them
/// go to `unplaced` when it is given.
ClusterRound cluster_round(const std::vector<uint32_t> &chosen, const std::vector<MotionPoint> &points,
			   const GroupMotionContext &context, const GroupParams &params, const AffinityParams &affinity,
			   AffinityPropagation &workspace, std::vector<std::vector<uint32_t>> &kept,
			   std::vector<uint32_t> *unplaced)
{
	// Seed 002's 6-d samples, each dimension over its scale: octave, row, column, disparity, flow u, flow v.
	cv::Mat samples = workspace.sample_buffer(static_cast<int>(chosen.size()), 6);
	for (size_t s = 0; s < chosen.size(); ++s) {
		const MotionPoint &p = points[chosen[s]];
		float disparity = 0;
		if (p.xyz && context.rig && (*p.xyz)[2] > 0)
			disparity = static_cast<float>(context.rig->fx * context.rig->baseline_m / (*p.xyz)[2]);
		float *row = samples.ptr<float>(static_cast<int>(s));
		row[0] = static_cast<float>(p.octave / params.octave_scale);
		row[1] = static_cast<float>(p.px.y / params.position_scale_px);
		row[2] = static_cast<float>(p.px.x / params.position_scale_px);
		row[3] = static_cast<float>(disparity / params.disparity_scale_px);
		row[4] = static_cast<float>(p.flow.x / params.flow_scale_px);
		row[5] = static_cast<float>(p.flow.y / params.flow_scale_px);
	}
	const int64_t start_ns = monotonic_ns();
	const AffinityResult &ap = workspace.cluster(samples, affinity);
	const ClusterRound round{ap.clusters, ap.iterations, ap.preference,
				 static_cast<double>(monotonic_ns() - start_ns) * 1e-6};
	std::vector<std::vector<uint32_t>> by_exemplar(chosen.size());
	for (size_t s = 0; s < chosen.size(); ++s)
		by_exemplar[static_cast<size_t>(ap.exemplar[s])].push_back(chosen[s]);
	const size_t min_points = min_group_points(params);
	const auto place = [&](std::vector<uint32_t> &&part) {
		if (part.size() >= min_points)
			kept.push_back(std::move(part));
		else if (unplaced != nullptr)
			unplaced->insert(unplaced->end(), part.begin(), part.end());
	};
	for (auto &members : by_exemplar) {
		if (members.size() < min_points) {
			if (unplaced != nullptr)
				unplaced->insert(unplaced->end(), members.begin(), members.end());
			continue;
		}
		// Members that do not move like the cluster's median (a flow that bled onto the background around
		// a mover, a stray point the clustering took along) leave it, by the rule points join a group by
		// (join_groups), so that the box and the velocities are the movers'.
		const cv::Point2f median = median_point(members, points, &MotionPoint::residual);
		const auto leaves = std::stable_partition(members.begin(), members.end(), [&](uint32_t i) {
			return moves_with(points[i].residual, median, member_tolerance(params));
		});
		if (unplaced != nullptr)
			unplaced->insert(unplaced->end(), leaves, members.end());
		members.erase(leaves, members.end());
		if (params.member_area_px2 > 0 && params.split_gap_cells >= 0) {
			// Half a cell of slack: the cells' positions have moved by their flow.
			const double reach = (params.split_gap_cells + 1.5) * std::sqrt(params.member_area_px2);
			for (auto &part : connected_parts(members, points, reach, params.split_same_depth))
				place(std::move(part));
		} else if (params.member_area_px2 <= 0 && params.split_gap_px > 0 &&
			   std::none_of(members.begin(), members.end(),
					[&](uint32_t i) { return points[i].xyz.has_value(); })) {
			// Feature points without depth (monocular footage) cut into their connected parts: without
			// the disparity dimension, walkers metres apart who move alike are one cluster whose box
			// spans the ground between them. With depth they are told apart by it, and the depth rules
			// (merge_alike) keep a near mover's scattered pieces together, which a cut in pixels breaks.
			for (auto &part : connected_parts(members, points, params.split_gap_px, 0))
				place(std::move(part));
		} else {
			place(std::move(members));
		}
	}
	return round;
}

/// A robust standard deviation of the points' residuals (the larger of u's and v's), pixels: most points are
/// the static scene's, so this is its noise. Infinite with too few points to tell.
double residual_noise_px(const std::vector<MotionPoint> &points)
{
	std::vector<float> u, v;
	for (const auto &p : points)
		if (std::isfinite(p.residual.x) && std::isfinite(p.residual.y)) {
			u.push_back(p.residual.x);
			v.push_back(p.residual.y);
		}
	if (u.size() < 10)
		return std::numeric_limits<double>::infinity();
	const auto mad = [](std::vector<float> &x) {
		const float m = median_of(x);
		for (float &e : x)
			e = std::abs(e - m);
		return 1.4826 * median_of(x);
	};
	return std::max(mad(u), mad(v));
}

} // namespace

void PositionHistory::push(const Entry &entry)
{
	entries[next] = entry;
	next = (next + 1) % kCapacity;
	size = std::min(size + 1, kCapacity);
}

const PositionHistory::Entry &PositionHistory::newest(size_t i) const
{
	return entries[(next + kCapacity - 1 - i) % kCapacity];
}

namespace {

/// Two estimates with positive variances weighted by the inverse of their variances; their errors taken as
/// fully correlated (they come from the same depths), so the weighted mean's spread is the weighted mean of
/// their spreads, not the smaller spread of two independent ones.
Estimate fuse_correlated(const Estimate &a, const Estimate &b)
{
	const double inverse = 1 / a.variance + 1 / b.variance;
	const double spread = (1 / std::sqrt(a.variance) + 1 / std::sqrt(b.variance)) / inverse;
	return Estimate{(a.value / a.variance + b.value / b.variance) / inverse, spread * spread};
}

} // namespace

std::optional<Estimate> velocity_along(const PositionHistory &history, double window_s, const cv::Vec3d &ray)
{
	if (history.size == 0 || window_s <= 0)
		return std::nullopt;
	const double t_end = history.newest(0).t_s;
	size_t n = 0, measured = 0;
	double mean_t = 0, mean_p = 0, mean_v = 0;
	for (; n < history.size && t_end - history.newest(n).t_s <= window_s; ++n) {
		const auto &e = history.newest(n);
		mean_t += e.t_s;
		mean_p += e.world.dot(ray);
		if (e.measured_velocity) {
			mean_v += e.measured_velocity->dot(ray);
			++measured;
		}
	}
	constexpr size_t kFewest = 4;
	if (n < kFewest || measured < kFewest || t_end - history.newest(n - 1).t_s < 0.5 * window_s)
		return std::nullopt;
	mean_t /= static_cast<double>(n);
	mean_p /= static_cast<double>(n);
	mean_v /= static_cast<double>(measured);
	double stt = 0, stp = 0, spread_v = 0;
	for (size_t i = 0; i < n; ++i) {
		const auto &e = history.newest(i);
		stt += (e.t_s - mean_t) * (e.t_s - mean_t);
		stp += (e.t_s - mean_t) * (e.world.dot(ray) - mean_p);
		if (e.measured_velocity)
			spread_v += (e.measured_velocity->dot(ray) - mean_v) * (e.measured_velocity->dot(ray) - mean_v);
	}
	if (stt <= 0)
		return std::nullopt;
	const double slope = stp / stt;
	double residuals = 0;
	for (size_t i = 0; i < n; ++i) {
		const auto &e = history.newest(i);
		const double r = e.world.dot(ray) - mean_p - slope * (e.t_s - mean_t);
		residuals += r * r;
	}
	const double slope_variance = residuals / static_cast<double>(n - 2) / stt;
	const double mean_variance = spread_v / static_cast<double>(measured - 1) / static_cast<double>(measured);
	if (!std::isfinite(slope_variance) || !std::isfinite(mean_variance))
		return std::nullopt;
	// A measure without spread is exact and wins outright (constructed data; both: their mean).
	if (slope_variance <= 0 || mean_variance <= 0)
		return Estimate{slope_variance <= 0 && mean_variance <= 0 ? (slope + mean_v) / 2
									  : (slope_variance <= 0 ? slope : mean_v),
				0};
	// Both measures come from the same members' depths, so their errors go together.
	return fuse_correlated({slope, slope_variance}, {mean_v, mean_variance});
}

namespace {

/// The largest lag-one correlation measured_spread credits (5.4 times fewer independent measurements).
constexpr double kMaxPersistence = 0.7;

} // namespace

namespace {

using MeasuredEntries = std::array<const PositionHistory::Entry *, PositionHistory::kCapacity>;

/// The newest `count` (at most) entries of `history` that carry a measured velocity, newest first, into
/// `entries`; returns how many.
size_t newest_measured(const PositionHistory &history, size_t count, MeasuredEntries &entries)
{
	size_t n = 0;
	for (size_t i = 0; i < history.size && n < count; ++i)
		if (history.newest(i).measured_velocity)
			entries[n++] = &history.newest(i);
	return n;
}

} // namespace

std::optional<MeasuredSpread> measured_spread(const PositionHistory &history, size_t count, const cv::Vec3d &ray)
{
	MeasuredEntries entries{};
	const size_t n = newest_measured(history, count, entries);
	std::array<cv::Vec3d, PositionHistory::kCapacity> velocities;
	for (size_t i = 0; i < n; ++i)
		velocities[i] = *entries[i]->measured_velocity;
	if (n < 4)
		return std::nullopt;
	cv::Vec3d mean(0, 0, 0);
	for (size_t i = 0; i < n; ++i)
		mean += velocities[i];
	mean /= static_cast<double>(n);
	MeasuredSpread spread;
	double along_lag = 0, across_lag = 0; // sums of products of consecutive deviations
	for (size_t i = 0; i < n; ++i) {
		const cv::Vec3d d = velocities[i] - mean;
		const double along = d.dot(ray);
		spread.along += along * along;
		spread.across += d.dot(d) - along * along;
		if (i + 1 < n) {
			const cv::Vec3d next = velocities[i + 1] - mean;
			const double next_along = next.dot(ray);
			along_lag += along * next_along;
			across_lag += (d - along * ray).dot(next - next_along * ray);
		}
	}
	// A group's error persists from frame to frame (its members change a few at a time), so an average over n
	// measurements is worth fewer independent ones: with lag-one correlation r, (1 - r) / (1 + r) of them.
	const auto persistence = [](double lag, double total) {
		const double r = total > 0 ? std::clamp(lag / total, 0.0, kMaxPersistence) : 0;
		return (1 + r) / (1 - r);
	};
	spread.along_persistence = persistence(along_lag, spread.along);
	spread.across_persistence = persistence(across_lag, spread.across);
	// Over few samples the sample variance is itself uncertain: the variance of Student's t with n - 1 degrees
	// of freedom, (n - 1) / (n - 3) times it, so that a young group's spread is not read as sure.
	const auto dof = static_cast<double>(n - 1);
	const double widen = dof / (dof - 2);
	spread.along *= widen / dof;
	spread.across *= widen / (2.0 * dof);
	return spread;
}

std::optional<VelocityTrend> velocity_trend(const PositionHistory &history, size_t count)
{
	MeasuredEntries measured{};
	const size_t n = newest_measured(history, count, measured);
	if (n < 4)
		return std::nullopt;
	double mean_t = 0;
	cv::Vec3d mean_v(0, 0, 0);
	for (size_t i = 0; i < n; ++i) {
		mean_t += measured[i]->t_s;
		mean_v += *measured[i]->measured_velocity;
	}
	mean_t /= static_cast<double>(n);
	mean_v /= static_cast<double>(n);
	double stt = 0;
	cv::Vec3d stv(0, 0, 0);
	for (size_t i = 0; i < n; ++i) {
		const double dt = measured[i]->t_s - mean_t;
		stt += dt * dt;
		stv += dt * (*measured[i]->measured_velocity - mean_v);
	}
	if (stt <= 0)
		return std::nullopt;
	VelocityTrend trend{stv / stt, {}};
	cv::Vec3d residuals(0, 0, 0);
	for (size_t i = 0; i < n; ++i) {
		const double dt = measured[i]->t_s - mean_t;
		const cv::Vec3d r = *measured[i]->measured_velocity - mean_v - dt * trend.acceleration;
		residuals += r.mul(r);
	}
	trend.variance = residuals / (static_cast<double>(n - 2) * stt);
	return trend;
}

namespace {

/// `smoothed` with its component along `ray` (the line of sight in the world, unit length) replaced by
/// `along`.
cv::Vec3d along_sight_from(const cv::Vec3d &smoothed, double along, const cv::Vec3d &ray)
{
	return smoothed + (along - smoothed.dot(ray)) * ray;
}

/// A young group's velocity along the sight line from its members' anchors (`anchored`, per axis) and its
/// averaged frame-to-frame measurements (`averaged`, with their variance where known), weighted by the inverse
/// of their variances; the two measure the same depths in part, so the weighted mean's spread is taken as the
/// weighted mean of theirs. Without the averages' variance, the anchors' alone.
std::optional<Estimate> along_from_anchors(const Estimate3 &anchored, const cv::Vec3d &ray, double averaged,
					   std::optional<double> averaged_variance)
{
	const double value = anchored.value.dot(ray);
	double variance = 0;
	for (int a = 0; a < 3; ++a)
		variance += ray[a] * ray[a] * anchored.variance[a];
	if (!std::isfinite(variance) || variance <= 0)
		return std::nullopt;
	if (!averaged_variance || !std::isfinite(*averaged_variance) || *averaged_variance <= 0)
		return Estimate{value, variance};
	return fuse_correlated({value, variance}, {averaged, *averaged_variance});
}

/// A group's velocity spread is taken over its newest this-many measurements: about half a second at 30 fps,
/// enough for a variance, and short enough that a walker's turn does not swell it.
constexpr size_t kSpreadMeasurements = 16;

} // namespace

GroupOutput find_groups(const std::vector<MotionPoint> &points, const GroupMemory *previous,
			const GroupMotionContext &context, const GroupParams &given, AffinityPropagation &workspace,
			const std::vector<uint32_t> *strong)
{
	GroupParams params = given;
	if (strong == nullptr && params.members == GroupMembers::Flow && params.noise_sigmas > 0)
		params.min_flow_px =
			std::min(given.min_flow_px,
				 std::max(given.min_flow_floor_px, given.noise_sigmas * residual_noise_px(points)));
	GroupOutput out;
	out.group_of_point.assign(points.size(), -1);
	out.strong = strong != nullptr ? *strong : strong_motion(points, params);
	// An even subsample beyond the cap keeps the clustering's cost bounded whatever the scene.
	std::vector<uint32_t> chosen = out.strong;
	if (params.max_points > 0 && chosen.size() > static_cast<size_t>(params.max_points)) {
		std::vector<uint32_t> thinned;
		const double step = static_cast<double>(chosen.size()) / params.max_points;
		for (int k = 0; k < params.max_points; ++k)
			thinned.push_back(chosen[static_cast<size_t>(k * step)]);
		chosen = std::move(thinned);
	}
	std::vector<Cluster> clusters;
	if (!chosen.empty()) {
		std::vector<std::vector<uint32_t>> kept;
		std::vector<uint32_t> unplaced;
		const ClusterRound first = cluster_round(chosen, points, context, params, params.affinity, workspace,
							 kept, params.regroup_unplaced ? &unplaced : nullptr);
		out.clusters = first.clusters;
		out.ap_iterations = first.iterations;
		out.clustering_ms = first.clustering_ms;
		// The points the first round placed in no group cluster once more among themselves: a small mover
		// (a few points) beside a large one is among the large one's nearest samples, so Affinity
		// Propagation hands it the large one's exemplar, and the member rule then takes it out again. At a
		// share (regroup_preference_scale) of the first round's preference: these are several movers'
		// leftovers, which the first round's (from the farthest pair in the frame) hands one exemplar, so that
		// the member rule keeps only one mover's; the seed's rule on these points alone (their own farthest
		// pair) would swing with how they happen to lie, and cut a lone small mover into pieces under
		// min_points.
		if (unplaced.size() >= min_group_points(params)) {
			AffinityParams again = params.affinity;
			again.preference = first.preference * params.regroup_preference_scale;
			const ClusterRound second =
				cluster_round(unplaced, points, context, params, again, workspace, kept, nullptr);
			out.ap_iterations += second.iterations;
			*out.clustering_ms += second.clustering_ms;
		}
		// The fill rule on each piece before the merge: pieces of one mover joined across the gaps between
		// them fill their common box less than each its own.
		if (params.member_area_px2 > 0) {
			std::erase_if(kept, [&](const std::vector<uint32_t> &members) {
				return box_fill(members, points, params) < params.min_box_fill;
			});
		}
		// A piece most of whose members moved only along their edges is the aperture problem's, not a
		// mover's: a streaky patch of the static scene whose flow slid along the streaks as the camera
		// turned. A mover's cells on edges are a minority among its textured ones.
		std::erase_if(kept, [&](const std::vector<uint32_t> &members) {
			const auto sliding = std::count_if(members.begin(), members.end(), [&](uint32_t m) {
				return slides_along_edge(points[m], params.min_flow_px);
			});
			return 2 * static_cast<size_t>(sliding) > members.size();
		});
		merge_alike(kept, points, params, context.rig ? context.rig->fx : 0.0);
		for (auto &members : kept)
			clusters.push_back(
				measure(std::move(members), points, context, static_cast<float>(params.box_margin_px)));
	}

	// Tracks: each previous group predicted forward by its image velocity; greedy one-to-one by distance.
	const std::vector<TrackedGroup> none;
	const std::vector<TrackedGroup> &before = previous != nullptr ? previous->groups : none;
	out.memory.next_id = previous != nullptr ? previous->next_id : 1;
	struct Candidate {
		double distance;
		size_t cluster, track;
	};
	// Where each track's image velocity takes its centre and box since it was last seen, and how far from
	// that centre it takes a cluster (a large mover's centre wanders further).
	struct Prediction {
		cv::Point2f centre;
		cv::Rect2f box;
		double gate;
	};
	std::vector<Prediction> predicted(before.size());
	for (size_t t = 0; t < before.size(); ++t) {
		const cv::Point2f shift = before[t].image_velocity_pxps * static_cast<float>(context.dt_s) *
					  static_cast<float>(1 + before[t].missed_frames);
		predicted[t] = {
			before[t].centre + shift,
			{before[t].box.tl() + shift, before[t].box.size()},
			std::max(params.association_px, 0.5 * std::hypot(before[t].box.width, before[t].box.height))};
	}
	// The share of the smaller of a track's predicted box and a cluster's box that the other covers.
	const auto overlap_share = [&](size_t t, const Cluster &cluster) {
		const float smaller = std::min(predicted[t].box.area(), cluster.box.area());
		return smaller > 0 ? (predicted[t].box & cluster.box).area() / smaller : 0.F;
	};
	// A published group whose predicted box lies behind a group found in this frame that moves otherwise is
	// hidden by it, not gone: remembered (published on only for coast_frames) long enough for a walker to pass in
	// front of another (occlusion_frames), and while it is missed it takes a cluster only when they move alike. The
	// mover in front, whose cluster may lie nearer the hidden one's predicted centre than the front one's own track
	// does, moves otherwise; a cluster that moves alike is as likely the same mover seen whole.
	std::vector<uint8_t> hidden(before.size(), 0);
	for (size_t t = 0; t < before.size() && params.occlusion_frames > 0; ++t) {
		if (!before[t].published)
			continue;
		const std::optional<double> depth =
			before[t].published->position_m ? std::optional<double>((*before[t].published->position_m)[2])
							: std::nullopt;
		hidden[t] = std::any_of(clusters.begin(), clusters.end(), [&](const Cluster &c) {
			return !move_alike(c.residual, before[t].residual, params) &&
			       hidden_behind(predicted[t].box, depth, c.box,
					     c.position ? std::optional<double>((*c.position)[2]) : std::nullopt,
					     params.split_same_depth);
		});
	}
	std::vector<Candidate> candidates;
	for (size_t c = 0; c < clusters.size(); ++c)
		for (size_t t = 0; t < before.size(); ++t) {
			const double d = cv::norm(clusters[c].centre - predicted[t].centre);
			const bool hidden_and_missed = hidden[t] != 0 && before[t].missed_frames > 0;
			if (d <= predicted[t].gate &&
			    (!hidden_and_missed || move_alike(clusters[c].residual, before[t].residual, params)))
				candidates.push_back({d, c, t});
		}
	std::sort(candidates.begin(), candidates.end(),
		  [](const Candidate &a, const Candidate &b) { return a.distance < b.distance; });
	std::vector<int> track_of_cluster(clusters.size(), -1);
	std::vector<uint8_t> track_taken(before.size(), 0);
	for (const auto &cand : candidates)
		if (track_of_cluster[cand.cluster] < 0 && !track_taken[cand.track]) {
			track_of_cluster[cand.cluster] = static_cast<int>(cand.track);
			track_taken[cand.track] = 1;
		}
	// Then a cluster no track's centre reached takes the track whose predicted box it overlaps most, when
	// the two move alike (the join rule on their residuals): a large mover found in pieces has centres that
	// jump about inside it from frame to frame, farther than the gate, while its box stays put.
	for (size_t c = 0; c < clusters.size(); ++c) {
		if (track_of_cluster[c] >= 0)
			continue;
		double best_overlap = 0;
		for (size_t t = 0; t < before.size(); ++t) {
			if (track_taken[t])
				continue;
			const float share = overlap_share(t, clusters[c]);
			if (share > best_overlap && share >= 0.5F &&
			    move_alike(clusters[c].residual, before[t].residual, params)) {
				best_overlap = share;
				if (track_of_cluster[c] >= 0)
					track_taken[static_cast<size_t>(track_of_cluster[c])] = 0;
				track_of_cluster[c] = static_cast<int>(t);
				track_taken[t] = 1;
			}
		}
	}
	// A track left without a cluster that has one within its gate, on its predicted box and moving alike, is
	// a second track on that cluster's mover (seen in pieces, then whole; the other track took it by
	// distance). Of the two, the one seen longer goes on with the cluster and the other ends: not published
	// on beside it as a second group on the same mover. The gate keeps a wide cluster whose box merely
	// spans a track's from ending it.
	const auto lies_on = [&](const Cluster &cluster, size_t t) {
		return cv::norm(cluster.centre - predicted[t].centre) <= predicted[t].gate &&
		       overlap_share(t, cluster) >= 0.5F && move_alike(cluster.residual, before[t].residual, params);
	};
	std::vector<uint8_t> track_ended(before.size(), 0);
	for (size_t c = 0; c < clusters.size(); ++c)
		for (size_t t = 0; t < before.size(); ++t) {
			if (track_taken[t] || track_ended[t] || !lies_on(clusters[c], t))
				continue;
			const int holder = track_of_cluster[c];
			if (holder >= 0 && before[t].age_frames <= before[static_cast<size_t>(holder)].age_frames) {
				track_ended[t] = 1;
				continue;
			}
			if (holder >= 0) {
				track_taken[static_cast<size_t>(holder)] = 0;
				track_ended[static_cast<size_t>(holder)] = 1;
			}
			track_of_cluster[c] = static_cast<int>(t);
			track_taken[t] = 1;
		}
	const double fps = context.dt_s > 0 ? 1.0 / context.dt_s : 0;
	for (size_t c = 0; c < clusters.size(); ++c) {
		const Cluster &cluster = clusters[c];
		TrackedGroup g;
		const TrackedGroup *old =
			track_of_cluster[c] >= 0 ? &before[static_cast<size_t>(track_of_cluster[c])] : nullptr;
		g.id = old != nullptr ? old->id : out.memory.next_id++;
		g.age_frames = old != nullptr ? old->age_frames + 1 : 1;
		g.box = cluster.box;
		g.centre = cluster.centre;
		// A running mean over the track's first frames, then an exponential average: a young track is not
		// held to its first, noisiest measurement. The image velocity, which predicts where the group is
		// next, follows the camera's turns and keeps a lighter average than the metric velocities, which
		// are measured through the pose and depth, noisier frame to frame, and change only as the mover's
		// own gait does.
		const double weight = std::max(params.smoothing, 1.0 / g.age_frames);
		const double image_weight = std::max(params.image_smoothing, 1.0 / g.age_frames);
		const cv::Point2f image_velocity = cluster.flow * static_cast<float>(fps);
		g.image_velocity_pxps = old != nullptr
						? old->image_velocity_pxps * static_cast<float>(1 - image_weight) +
							  image_velocity * static_cast<float>(image_weight)
						: image_velocity;
		if (cluster.velocity)
			g.velocity_mps =
				blend(old != nullptr ? old->velocity_mps : std::nullopt, *cluster.velocity, weight);
		if (cluster.world_velocity)
			g.world_velocity_mps = blend(old != nullptr ? old->world_velocity_mps : std::nullopt,
						     *cluster.world_velocity, weight);
		g.residual = cluster.residual;
		g.clock_s = old != nullptr ? old->clock_s + context.dt_s * (1 + old->missed_frames) : 0;
		if (old != nullptr)
			g.positions = old->positions;
		// Published: the averaged velocities with their component along the line of sight from the track's
		// fitted positions (GroupParams::velocity_window_s), where it has them.
		std::optional<cv::Vec3d> world_velocity = g.world_velocity_mps, velocity = g.velocity_mps;
		std::optional<std::array<double, 2>> sigma; // along the sight, across it
		std::optional<double> speed_sigma;
		if (cluster.position && context.world_from_curr && cv::norm(*cluster.position) > 0) {
			g.positions.push(
				{g.clock_s, *context.world_from_curr * *cluster.position, cluster.world_velocity});
			const cv::Vec3d ray =
				context.world_from_curr->r * (*cluster.position / cv::norm(*cluster.position));
			// Plain values rather than an optional read in branches: GCC's -O1 (the TSan build) takes the
			// optional's members for uninitialised there.
			MeasuredSpread spread;
			bool has_spread = false;
			if (world_velocity)
				if (const auto measured = measured_spread(g.positions, kSpreadMeasurements, ray)) {
					spread = *measured;
					has_spread = true;
				}
			// The averages' spread: the running mean over the first 1 / smoothing measurements is their
			// mean, the exponential average after it weighs as (2 - w) / w independent ones.
			const double averaged = std::min(static_cast<double>(g.age_frames),
							 (2 - params.smoothing) / std::max(params.smoothing, 1e-6));
			const double averaged_along_variance = spread.along / averaged * spread.along_persistence;
			std::optional<Estimate> along = velocity_along(g.positions, params.velocity_window_s, ray);
			if (along)
				along->variance *= spread.along_persistence; // 1 without a spread
			else if (world_velocity && params.anchored_velocity && cluster.anchored_velocity)
				along = along_from_anchors(*cluster.anchored_velocity, ray, world_velocity->dot(ray),
							   has_spread ? std::optional<double>(averaged_along_variance)
								      : std::nullopt);
			if (along && world_velocity) {
				const cv::Vec3d fused = along_sight_from(*world_velocity, along->value, ray);
				// The camera-frame velocity is the mover's own plus the static scene's apparent one, so
				// it changes by as much.
				if (velocity)
					velocity =
						*velocity + context.world_from_curr->r.t() * (fused - *world_velocity);
				world_velocity = fused;
			}
			if (has_spread && world_velocity) {
				double along_variance = along ? along->variance : averaged_along_variance;
				double across_variance = spread.across / averaged * spread.across_persistence;
				// The speed's, to first order: its direction's share of each.
				const double speed = cv::norm(*world_velocity);
				const double share = speed > 0 ? world_velocity->dot(ray) / speed : 1;
				double speed_variance =
					share * share * along_variance + (1 - share * share) * across_variance;
				// An accelerating mover (a walker keeping pace with a rig that speeds up and slows
				// down, one turning back): the averages describe it as it was some time ago. The line
				// through the window's positions measures the velocity at the window's middle; the
				// exponential average is (1 - w) / w frames old. The squared trend overstates the
				// squared acceleration by its own variance (the measurements' noise), taken off.
				if (const auto trend = velocity_trend(g.positions, kSpreadMeasurements)) {
					const double window_lag_s = 0.5 * params.velocity_window_s;
					const double average_lag_s = context.dt_s * (1 - params.smoothing) /
								     std::max(params.smoothing, 1e-6);
					const double along_lag_s = along ? window_lag_s : average_lag_s;
					const cv::Vec3d &a = trend->acceleration;
					const double a_along = a.dot(ray);
					const cv::Vec3d a_across = a - a_along * ray;
					const cv::Vec3d ray_squared = ray.mul(ray);
					const double noise_along = trend->variance.dot(ray_squared);
					const double noise_across =
						trend->variance.dot(cv::Vec3d(1, 1, 1) - ray_squared);
					const double along_lag_sq = std::max(a_along * a_along - noise_along, 0.0) *
								    along_lag_s * along_lag_s;
					const double across_lag_sq =
						std::max(a_across.dot(a_across) - noise_across, 0.0) * average_lag_s *
						average_lag_s;
					along_variance += along_lag_sq;
					across_variance += across_lag_sq / 2; // per axis across
					// The speed's: the share of each along the velocity's direction.
					const double across_norm = cv::norm(a_across);
					const double across_share =
						speed > 0 && across_norm > 0
							? world_velocity->dot(a_across) / (speed * across_norm)
							: 0;
					speed_variance += share * share * along_lag_sq +
							  across_share * across_share * across_lag_sq;
				}
				sigma = {std::sqrt(along_variance), std::sqrt(across_variance)};
				speed_sigma = std::sqrt(speed_variance);
			}
		}
		if (g.age_frames < params.min_age_frames) {
			out.memory.groups.push_back(g);
			continue;
		}
		TargetGroup published;
		published.id = g.id;
		published.box_px = {g.box.x, g.box.y, g.box.x + g.box.width, g.box.y + g.box.height};
		published.point_count = static_cast<int>(cluster.members.size());
		published.age_frames = g.age_frames;
		published.image_velocity_pxps = {g.image_velocity_pxps.x, g.image_velocity_pxps.y};
		if (cluster.position)
			published.position_m = array_of(*cluster.position);
		if (cluster.extent)
			published.extent_m = array_of(*cluster.extent);
		if (velocity)
			published.velocity_mps = array_of(*velocity);
		if (world_velocity) {
			const cv::Vec3d &w = *world_velocity;
			published.world_velocity_mps = array_of(w);
			published.speed_mps = cv::norm(w);
			published.heading_rad = std::atan2(w[0], w[2]);
			published.velocity_sigma_mps = sigma;
			published.speed_sigma_mps = speed_sigma;
		}
		g.published = published;
		out.memory.groups.push_back(g);
		const int index = static_cast<int>(out.groups.size());
		out.groups.push_back(published);
		out.residuals.push_back(cluster.residual);
		for (const uint32_t i : cluster.members)
			out.group_of_point[i] = index;
	}
	// Groups not seen this frame are remembered a little while, so a short occlusion keeps the id; a
	// published one is published on for coast_frames, where its velocities take it; one leaving the view
	// through the edge band for edge_coast_frames.
	for (size_t t = 0; t < before.size(); ++t) {
		if (track_taken[t] || track_ended[t])
			continue;
		const bool leaving =
			before[t].published &&
			leaves_through_edge(predicted[t].box,
					    before[t].image_velocity_pxps * static_cast<float>(context.dt_s),
					    context.image_size, params.edge_band_px, params.edge_coast_frames);
		int remembered = leaving ? std::max(params.max_missed_frames, params.edge_coast_frames)
					 : params.max_missed_frames;
		if (hidden[t] != 0)
			remembered = std::max(remembered, params.occlusion_frames);
		const int coasts =
			leaving ? std::max(params.coast_frames, params.edge_coast_frames) : params.coast_frames;
		if (before[t].missed_frames >= remembered)
			continue;
		TrackedGroup kept = before[t];
		++kept.missed_frames;
		out.memory.groups.push_back(kept);
		// No longer than it had been published for: a patch of flow noise that clustered for a frame
		// or two is not carried on as long as a mover followed for a second.
		if (kept.published && kept.missed_frames <= coasts &&
		    kept.missed_frames <= kept.published->age_frames - params.min_age_frames) {
			out.groups.push_back(coasted(kept, context.dt_s, context.image_size));
			out.residuals.push_back(kept.residual);
		}
	}
	// Points inside a box moving with its group belong to it too (they may have missed the strong set).
	join_groups(points, out, params, out.group_of_point);
	return out;
}

} // namespace stereod::vision
