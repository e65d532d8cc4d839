// The static map (core/geometry/static_map.hpp) on constructed frames with known poses.
#include <gtest/gtest.h>

#include "core/geometry/static_map.hpp"

using namespace stereod;
using namespace stereod::geometry;

namespace {

/// A frame whose camera stands `x_m` to the right of the world origin, looking along z, holding `points`.
FrameResult frame_at(uint64_t seq, double x_m, std::vector<LabelledPoint> points, bool valid = true)
{
	FrameResult r;
	r.seq = seq;
	EgoMotion ego;
	ego.valid = valid;
	ego.t_world_curr = std::array<double, 16>{1, 0, 0, x_m, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
	r.ego = ego;
	r.points = std::move(points);
	return r;
}

LabelledPoint point(PointLabel label, float x, float y, float z, float u = 10, float v = 10)
{
	LabelledPoint p;
	p.u = u;
	p.v = v;
	p.label = label;
	p.xyz_m = std::array<float, 3>{x, y, z};
	return p;
}

} // namespace

TEST(StaticMap, PlacesStaticPointsInTheWorldAndLeavesMoversOut)
{
	StaticMap map({0.1, 2, 20.0});
	// The same world point (1, 0, 5) seen from x = 0 and from x = 0.5 (so at camera x 1 and 0.5); a mover's
	// point seen twice at one place; a static point seen once only; a frame without a valid pose.
	EXPECT_EQ(map.add(frame_at(1, 0.0,
				   {point(PointLabel::Static, 1, 0, 5), point(PointLabel::Dynamic, -1, 0, 4),
				    point(PointLabel::Static, 3, 0, 7)})),
		  2);
	EXPECT_EQ(map.add(frame_at(2, 0.5,
				   {point(PointLabel::Static, 0.5F, 0, 5), point(PointLabel::Dynamic, -1.5F, 0, 4)})),
		  1);
	EXPECT_EQ(map.add(frame_at(3, 9.0, {point(PointLabel::Static, 0, 0, 5)}, false)), 0);
	EXPECT_EQ(map.frames_used(), 2U);
	const auto points = map.points();
	ASSERT_EQ(points.size(), 1U) << "seen once, and a mover: neither makes the map";
	EXPECT_NEAR(points[0].xyz_m[0], 1.0F, 1e-6F);
	EXPECT_NEAR(points[0].xyz_m[2], 5.0F, 1e-6F);
	EXPECT_EQ(points[0].observations, 2);
}

TEST(StaticMap, ColoursFromTheImageAndOneObservationPerFrame)
{
	StaticMap map({0.1, 2, 20.0});
	cv::Mat image(20, 20, CV_8UC3, cv::Scalar(10, 20, 30));
	// Two points of one frame in one voxel count one observation: still below min_observations.
	map.add(frame_at(1, 0, {point(PointLabel::Static, 1, 1, 5), point(PointLabel::Static, 1.01F, 1, 5)}), image);
	EXPECT_TRUE(map.points().empty());
	map.add(frame_at(2, 0, {point(PointLabel::Static, 1.02F, 1, 5)}), image);
	const auto points = map.points();
	ASSERT_EQ(points.size(), 1U);
	EXPECT_EQ(points[0].colour, cv::Vec3b(10, 20, 30));
	// Too far to place: left out.
	StaticMap near({0.1, 1, 10.0});
	EXPECT_EQ(near.add(frame_at(1, 0, {point(PointLabel::Static, 0, 0, 12)})), 0);
}
