// Seed 002's global flow on constructed images with known motion: LK and DIS recover a known translation,
// a moving textured patch over a still textured background is the one group, cells get the depth of the
// stereo points around them, lone strong cells are dropped, and feature points join a group only when they
// move with it.
#include <cmath>
#include <functional>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/vision/dense_motion.hpp"
#include "core/vision/groups.hpp"
#include "test_images.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

/// Smoothed noise: texture at every scale LK and DIS look at.
cv::Mat texture(cv::Size size, unsigned seed)
{
	return test::smoothed_noise(size, seed, 1.5);
}

using test::shifted;

/// Median of the measured cells' flow, over the cells at least `margin` cells from the border.
cv::Point2f median_flow(const CellFlow &cells, int margin, size_t &measured, size_t &interior)
{
	std::vector<float> u, v;
	interior = 0;
	for (int r = margin; r < cells.rows - margin; ++r)
		for (int c = margin; c < cells.cols - margin; ++c) {
			++interior;
			const auto i = static_cast<size_t>(r * cells.cols + c);
			if (cells.valid[i] == 0)
				continue;
			u.push_back(cells.flow[i].x);
			v.push_back(cells.flow[i].y);
		}
	measured = u.size();
	if (u.empty())
		return {NAN, NAN};
	std::nth_element(u.begin(), u.begin() + static_cast<std::ptrdiff_t>(u.size() / 2), u.end());
	std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
	return {u[u.size() / 2], v[v.size() / 2]};
}

/// The pipeline's grouping of the dense flow's cells, frame after frame: the group parameters set as the
/// pipeline sets them for cells, the tracks carried on from one step to the next.
struct CellGrouping {
	DenseFlowParams flow;
	GroupParams groups;
	cv::Ptr<cv::DISOpticalFlow> dis;
	AffinityPropagation workspace;
	GroupMemory memory;
	bool first = true;

	explicit CellGrouping(const DenseFlowParams &flow_params) : flow(flow_params)
	{
		groups.members = GroupMembers::Flow;
		groups.box_margin_px = 0.5 * flow.step_px;
		groups.member_area_px2 = flow.step_px * flow.step_px;
		groups.min_points = flow.min_cells;
	}

	/// The groups from `before` to `now`; with `depth_of`, every cell gets that depth by its column.
	GroupOutput step(const cv::Mat &before, const cv::Mat &now, const std::function<float(float)> &depth_of = {})
	{
		const CellFlow cells =
			dense_flow(dense_flow_image(before, flow), dense_flow_image(now, flow), now.size(), flow, dis);
		std::vector<MotionPoint> points = cell_motion(cells, flow, {}, {}, {});
		if (depth_of)
			for (MotionPoint &p : points)
				p.xyz = cv::Vec3f(0, 0, depth_of(p.px.x));
		const std::vector<uint32_t> strong = supported_cells(strong_motion(points, groups), cells.cols,
								     cells.rows, flow.min_strong_neighbours);
		GroupMotionContext context;
		context.dt_s = 0.1;
		GroupOutput out = find_groups(points, first ? nullptr : &memory, context, groups, workspace, &strong);
		memory = out.memory;
		first = false;
		return out;
	}
};

} // namespace

TEST(DenseFlow, RecoversAKnownTranslation)
{
	const cv::Mat prev = texture({320, 240}, 11);
	const cv::Point2f motion(3.4F, -2.2F);
	const cv::Mat cur = shifted(prev, motion);
	for (const GroupFlow method : {GroupFlow::PyrLk, GroupFlow::Dis})
		for (const double scale : {1.0, 0.5}) {
			DenseFlowParams params;
			params.method = method;
			params.scale = scale;
			cv::Ptr<cv::DISOpticalFlow> dis;
			const CellFlow cells = dense_flow(dense_flow_image(prev, params), dense_flow_image(cur, params),
							  prev.size(), params, dis);
			ASSERT_EQ(cells.cols, 40);
			ASSERT_EQ(cells.rows, 30);
			size_t measured = 0, interior = 0;
			const cv::Point2f median = median_flow(cells, 2, measured, interior);
			const std::string what = std::string(method == GroupFlow::PyrLk ? "lk" : "dis") + " at scale " +
						 std::to_string(scale);
			EXPECT_GE(measured, interior * 9 / 10) << what << ": most interior cells measured";
			// DIS's ultrafast preset is the coarser of the two (measured: 0.19 px off at half scale).
			const double tolerance = method == GroupFlow::PyrLk ? 0.1 : 0.3;
			EXPECT_NEAR(median.x, motion.x, tolerance) << what;
			EXPECT_NEAR(median.y, motion.y, tolerance) << what;
		}
}

TEST(DenseFlow, StillImagesHaveNoStrongCell)
{
	const cv::Mat image = texture({320, 240}, 5);
	DenseFlowParams params;
	params.method = GroupFlow::PyrLk;
	cv::Ptr<cv::DISOpticalFlow> dis;
	const cv::Mat small = dense_flow_image(image, params);
	const CellFlow cells = dense_flow(small, small, image.size(), params, dis);
	const std::vector<MotionPoint> points = cell_motion(cells, params, {}, {}, {});
	GroupParams group_params;
	EXPECT_TRUE(strong_motion(points, group_params).empty());
}

TEST(DenseFlow, CellsOnStripesAreOnAnEdge)
{
	// The left half vertical stripes (the grey level changes along x only), the right half texture: with
	// aperture_ratio set, the stripes' cells have the direction across their edges, sideways, and the
	// textured cells none; with it off, no cell has one.
	const cv::Size size(320, 240);
	cv::Mat image = texture(size, 9);
	for (int y = 0; y < size.height; ++y)
		for (int x = 0; x < size.width / 2; ++x)
			image.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(128 + 100 * std::sin(x * 0.4));
	DenseFlowParams params;
	params.method = GroupFlow::PyrLk;
	params.aperture_ratio = 0.1;
	cv::Ptr<cv::DISOpticalFlow> dis;
	const cv::Mat small = dense_flow_image(image, params);
	const CellFlow cells = dense_flow(small, small, image.size(), params, dis);
	ASSERT_EQ(cells.across.size(), cells.flow.size());
	int stripes = 0, on_edge = 0, textured = 0, off_edge = 0;
	for (int r = 1; r + 1 < cells.rows; ++r)
		for (int c = 1; c + 1 < cells.cols; ++c) {
			const cv::Point2f a = cells.across[static_cast<size_t>(r * cells.cols + c)];
			if ((c + 1) * params.step_px < size.width / 2 - 8) {
				++stripes;
				on_edge += std::abs(a.x) > 0.99F && std::abs(a.y) < 0.1F ? 1 : 0;
			} else if (c * params.step_px > size.width / 2 + 8) {
				++textured;
				off_edge += a.x == 0 && a.y == 0 ? 1 : 0;
			}
		}
	EXPECT_GE(on_edge, stripes * 9 / 10) << on_edge << " of " << stripes << " stripe cells";
	EXPECT_GE(off_edge, textured * 9 / 10) << off_edge << " of " << textured << " textured cells";
	params.aperture_ratio = 0;
	EXPECT_TRUE(dense_flow(small, small, image.size(), params, dis).across.empty());
}

TEST(DenseFlow, MovingPatchIsTheOneGroup)
{
	// A still textured background with a 64x96 textured patch moving 4 px per frame to the right: the
	// cells on the patch are the strong ones, they make one group whose box is the patch's, published from
	// the second pair on, with one id and an image velocity of 4 px per frame.
	const cv::Size size(480, 320);
	const cv::Mat background = texture(size, 3);
	const cv::Mat patch = texture({64, 96}, 4);
	auto frame = [&](int n) {
		cv::Mat image = background.clone();
		patch.copyTo(image(cv::Rect(100 + 4 * n, 120, patch.cols, patch.rows)));
		return image;
	};
	for (const GroupFlow method : {GroupFlow::PyrLk, GroupFlow::Dis}) {
		DenseFlowParams params;
		params.method = method;
		params.scale = 1.0;
		GroupParams group_params;
		group_params.members = GroupMembers::Flow;
		group_params.box_margin_px = 0.5 * params.step_px;
		cv::Ptr<cv::DISOpticalFlow> dis;
		AffinityPropagation workspace;
		GroupMemory memory;
		GroupMotionContext context;
		context.dt_s = 0.1;
		int id = 0;
		for (int n = 1; n <= 6; ++n) {
			const CellFlow cells = dense_flow(dense_flow_image(frame(n - 1), params),
							  dense_flow_image(frame(n), params), size, params, dis);
			const std::vector<MotionPoint> points = cell_motion(cells, params, {}, {}, {});
			const std::vector<uint32_t> strong =
				supported_cells(strong_motion(points, group_params), cells.cols, cells.rows,
						params.min_strong_neighbours);
			GroupOutput out = find_groups(points, n == 1 ? nullptr : &memory, context, group_params,
						      workspace, &strong);
			memory = out.memory;
			const std::string what =
				std::string(method == GroupFlow::PyrLk ? "lk" : "dis") + " frame " + std::to_string(n);
			if (n == 1) {
				EXPECT_TRUE(out.groups.empty()) << what;
				continue;
			}
			// LK, the seed's method, is exact here. DIS's ultrafast preset smears the flow over ~8 px
			// around the patch (its box grows, its mean flow falls ~12 %) and its border cells can make a
			// second, slower group on the patch's edge: its checks are looser, but no group may be off
			// the patch.
			const bool lk = method == GroupFlow::PyrLk;
			ASSERT_FALSE(out.groups.empty()) << what;
			if (lk)
				EXPECT_EQ(out.groups.size(), 1u) << what;
			else
				EXPECT_LE(out.groups.size(), 2u) << what;
			const cv::Rect2f truth(100.F + 4.F * static_cast<float>(n), 120.F, 64.F, 96.F);
			auto box_of = [](const TargetGroup &g) {
				return cv::Rect2f(g.box_px[0], g.box_px[1], g.box_px[2] - g.box_px[0],
						  g.box_px[3] - g.box_px[1]);
			};
			for (const TargetGroup &other : out.groups)
				EXPECT_GT((truth & box_of(other)).area(), 0.5F * box_of(other).area()) << what;
			const TargetGroup &g = *std::max_element(out.groups.begin(), out.groups.end(),
								 [](const TargetGroup &a, const TargetGroup &b) {
									 return a.point_count < b.point_count;
								 });
			if (id == 0)
				id = g.id;
			EXPECT_EQ(g.id, id) << what;
			const cv::Rect2f box = box_of(g);
			const float overlap = (truth & box).area() / (truth | box).area();
			EXPECT_GT(overlap, lk ? 0.85F : 0.6F) << what << ": box " << box << " against " << truth;
			EXPECT_NEAR(g.image_velocity_pxps[0], 40, lk ? 1 : 8) << what;
			EXPECT_NEAR(g.image_velocity_pxps[1], 0, lk ? 1 : 4) << what;
		}
	}
}

TEST(DenseFlow, MoversApartAreCutIntoRegionsUnlessAtOneDepth)
{
	// Two 48x96 textured patches 40 px (5 cells) apart, both moving 4 px per frame to the right (one motion,
	// two regions), and a third far off moving up. With every sample linked and half the seed's preference
	// (fewer, larger clusters, as crowded footage gives), Affinity Propagation puts the two in one cluster;
	// cut into connected regions (split_gap_cells 2), each patch is one group with its box on it. With depth,
	// the two stay one group when they are at the same distance (5 m both: a weakly textured mover's spots),
	// and are cut when they are not (5 m and 8 m).
	const cv::Size size(640, 480);
	const cv::Mat background = texture(size, 3);
	const cv::Mat patch_a = texture({48, 96}, 4), patch_b = texture({48, 96}, 5), patch_c = texture({48, 48}, 6);
	auto frame = [&](int n) {
		cv::Mat image = background.clone();
		patch_a.copyTo(image(cv::Rect(100 + 4 * n, 120, patch_a.cols, patch_a.rows)));
		patch_b.copyTo(image(cv::Rect(188 + 4 * n, 120, patch_b.cols, patch_b.rows)));
		patch_c.copyTo(image(cv::Rect(560, 360 - 4 * n, patch_c.cols, patch_c.rows)));
		return image;
	};
	DenseFlowParams params;
	params.method = GroupFlow::PyrLk;
	params.scale = 1.0;
	struct Case {
		int gap;
		float depth_b; // patch B's depth; A's is 5 m; 0: no depth anywhere
		size_t groups;
	};
	for (const Case c : {Case{2, 0, 3}, Case{-1, 0, 2}, Case{2, 5, 2}, Case{2, 8, 3}}) {
		const int gap = c.gap;
		CellGrouping grouping(params);
		grouping.groups.split_gap_cells = gap;
		// Fewer, larger clusters (every sample linked, a lower preference), as crowded footage gives.
		grouping.groups.affinity.neighbours = 1000;
		grouping.groups.affinity.preference_scale = 2;
		for (int n = 1; n <= 4; ++n) {
			const auto depth = [&](float x) { return x < 170.F ? 5.F : c.depth_b; };
			const GroupOutput out = c.depth_b > 0 ? grouping.step(frame(n - 1), frame(n), depth)
							      : grouping.step(frame(n - 1), frame(n));
			if (n == 1)
				continue;
			const std::string what = "gap " + std::to_string(gap) + ", depth " + std::to_string(c.depth_b) +
						 ", frame " + std::to_string(n);
			// Not cut, or at one depth: the two patches that move alike come out as one group.
			ASSERT_EQ(out.groups.size(), c.groups) << what;
			if (c.groups == 2)
				continue;
			const float d = 4.F * static_cast<float>(n);
			const std::vector<cv::Rect2f> truths = {{100.F + d, 120.F, 48.F, 96.F},
								{188.F + d, 120.F, 48.F, 96.F},
								{560.F, 360.F - d, 48.F, 48.F}};
			std::vector<int> found(truths.size(), 0);
			for (const TargetGroup &g : out.groups) {
				const cv::Rect2f box(g.box_px[0], g.box_px[1], g.box_px[2] - g.box_px[0],
						     g.box_px[3] - g.box_px[1]);
				for (size_t t = 0; t < truths.size(); ++t)
					if ((truths[t] & box).area() / (truths[t] | box).area() > 0.8F)
						++found[t];
			}
			EXPECT_EQ(found, std::vector<int>(truths.size(), 1)) << what;
		}
	}
}

TEST(DenseFlow, PiecesOfOneMoverAtOneDepthAreOneGroup)
{
	// Two 48x96 textured patches moving alike 4 px per frame to the right, `gap` px apart, clustered with the
	// pipeline's settings (k nearest, the seed's preference). A mover's pieces that move alike and lie at one
	// depth are one group when the gap between them is no wider than the larger piece's longer side (96 px
	// here), two when the depths differ (5 m and 8 m), when there is no depth (monocular: two people walking
	// alike), or when they are farther apart than that.
	const cv::Size size(640, 480);
	const cv::Mat background = texture(size, 13);
	const cv::Mat patch_a = texture({48, 96}, 14), patch_b = texture({48, 96}, 15);
	DenseFlowParams params;
	params.method = GroupFlow::PyrLk;
	params.scale = 1.0;
	struct Case {
		int gap;
		float depth_b; // patch B's depth; A's is 5 m; 0: no depth anywhere
		size_t groups;
	};
	for (const Case c : {Case{64, 5, 1}, Case{64, 8, 2}, Case{64, 0, 2}, Case{240, 5, 2}}) {
		const int b_x = 100 + 48 + c.gap;
		auto frame = [&](int n) {
			cv::Mat image = background.clone();
			patch_a.copyTo(image(cv::Rect(100 + 4 * n, 160, patch_a.cols, patch_a.rows)));
			patch_b.copyTo(image(cv::Rect(b_x + 4 * n, 160, patch_b.cols, patch_b.rows)));
			return image;
		};
		CellGrouping grouping(params);
		for (int n = 1; n <= 3; ++n) {
			const auto depth = [&](float x) { return x < static_cast<float>(b_x) - 8.F ? 5.F : c.depth_b; };
			const GroupOutput out = c.depth_b > 0 ? grouping.step(frame(n - 1), frame(n), depth)
							      : grouping.step(frame(n - 1), frame(n));
			if (n == 1)
				continue;
			EXPECT_EQ(out.groups.size(), c.groups)
				<< "gap " << c.gap << ", depth " << c.depth_b << ", frame " << n;
		}
	}
}

TEST(DenseFlow, CellDepthIsTheMedianAroundIt)
{
	// Cells of 8 px, radius 1: cell (2, 2) sees its own points (median 2 m) and its neighbour (3, 2)'s (4 m);
	// the median of the two cells' medians is taken as the upper one; far cells have none.
	DenseFlowParams params;
	params.step_px = 8;
	params.depth_radius_cells = 1;
	std::vector<cv::KeyPoint> keypoints;
	std::vector<cv::Vec3f> xyz;
	auto add = [&](float u, float v, float z) {
		keypoints.emplace_back(cv::Point2f(u, v), 7.F);
		xyz.emplace_back(0.F, 0.F, z);
	};
	add(17, 17, 1.F);
	add(18, 18, 2.F);
	add(19, 19, 9.F); // cell (2, 2): 1, 2, 9 -> 2
	add(25, 17, 4.F); // cell (3, 2): 4
	add(20, 20, NAN); // no depth: ignored
	const std::vector<float> depth = cell_depths(keypoints, xyz, 10, 8, params);
	ASSERT_EQ(depth.size(), 80u);
	EXPECT_FLOAT_EQ(depth[2 * 10 + 2], 4.F); // {2, 4}: nth_element's middle of two is the upper
	EXPECT_FLOAT_EQ(depth[2 * 10 + 1], 2.F); // sees only cell (2, 2)
	EXPECT_FLOAT_EQ(depth[2 * 10 + 4], 4.F); // sees only cell (3, 2)
	EXPECT_TRUE(std::isnan(depth[6 * 10 + 8]));
}

TEST(DenseFlow, LoneStrongCellsAreDropped)
{
	// A 3x3 block of strong cells and one lone cell on a 10x10 grid: with 2 neighbours required the block
	// stays whole (each of its cells has at least 3) and the lone cell goes.
	std::vector<uint32_t> strong;
	for (uint32_t r = 4; r < 7; ++r)
		for (uint32_t c = 4; c < 7; ++c)
			strong.push_back(r * 10 + c);
	strong.push_back(1 * 10 + 1);
	const std::vector<uint32_t> kept = supported_cells(strong, 10, 10, 2);
	EXPECT_EQ(kept.size(), 9u);
	EXPECT_EQ(std::count(kept.begin(), kept.end(), 11u), 0);
	EXPECT_EQ(supported_cells(strong, 10, 10, 0).size(), 10u);
}

TEST(DenseFlow, PointsJoinTheGroupHoldingTheCellUnderThem)
{
	// A 4x3 grid of 8 px cells; group 0 holds cells (1, 1) and (2, 1), group 1 holds (3, 2). Points are looked
	// up by their previous position (px - flow): the cells are the previous frame's grid.
	std::vector<int> group_of_cell(12, -1);
	group_of_cell[1 * 4 + 1] = 0;
	group_of_cell[1 * 4 + 2] = 0;
	group_of_cell[2 * 4 + 3] = 1;
	auto point = [](cv::Point2f before, cv::Point2f residual) {
		MotionPoint m;
		m.flow = {3, 0};
		m.px = before + m.flow;
		m.residual = residual;
		return m;
	};
	const cv::Point2f moving(1.5F, 0.F);
	const std::vector<MotionPoint> points = {
		point({10, 10}, moving),       // cell (1, 1): group 0
		point({6, 10}, moving),	       // now at (9, 10), in cell (1, 1), but was in (0, 1): none
		point({20, 12}, {0.2F, 0.1F}), // cell (2, 1), but stands still by its own measure
		point({20, 12}, {NAN, NAN}),   // cell (2, 1), no residual of its own
		point({28, 20}, {-2.F, 1.F}),  // cell (3, 2): group 1, whatever the direction
		point({12, 12}, moving),       // cell (1, 1), already in group 1: keeps it
		point({40, 10}, moving),       // beyond the grid
	};
	std::vector<int> group_of_point(points.size(), -1);
	group_of_point[5] = 1;
	join_by_cells(points, group_of_cell, 4, 3, 8, 0.5, group_of_point);
	EXPECT_EQ(group_of_point, (std::vector<int>{0, -1, -1, -1, 1, 1, -1}));
	// With no still floor the slow point joins; the one without a residual never does.
	std::fill(group_of_point.begin(), group_of_point.end(), -1);
	join_by_cells(points, group_of_cell, 4, 3, 8, 0.0, group_of_point);
	EXPECT_EQ(group_of_point, (std::vector<int>{0, -1, 0, -1, 1, 0, -1}));
}

TEST(Groups, PointsJoinOnlyWhenNearerTheGroupsMotionThanStill)
{
	// One group in box [0, 100]^2 moving (4, 0) px per frame. Inside: a point moving (3.5, 0.5) joins; one
	// still (0, 0) and one at (2, 0) (as near standing still as the group) do not; a point moving with the
	// group outside the box does not; a point without a residual does not.
	GroupOutput found;
	TargetGroup g;
	g.box_px = {0, 0, 100, 100};
	found.groups.push_back(g);
	found.residuals.emplace_back(4.F, 0.F);
	std::vector<MotionPoint> points(5);
	points[0].px = {50, 50};
	points[0].residual = {3.5F, 0.5F};
	points[1].px = {50, 50};
	points[1].residual = {0, 0};
	points[2].px = {50, 50};
	points[2].residual = {2, 0};
	points[3].px = {150, 50};
	points[3].residual = {4, 0};
	points[4].px = {50, 50};
	points[4].residual = {NAN, NAN};
	std::vector<int> group_of_point(points.size(), -1);
	join_groups(points, found, GroupParams{}, group_of_point);
	EXPECT_EQ(group_of_point, (std::vector<int>{0, -1, -1, -1, -1}));
}
