// Seed 001's keyframe selection (core/vision/keyframes.hpp): eq. 7's co-visibility index and eq. 6's motion
// test, with hand-computed answers.
#include <gtest/gtest.h>

#include "core/vision/keyframes.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

const geometry::StereoRig kRig{500, 500, 320, 240, 0.1};

/// What a camera at `world_from_camera` observes of the world point `w`.
StaticObservation observe(const geometry::Pose &world_from_camera, const cv::Vec3d &w)
{
	const cv::Vec3d c = world_from_camera.inverse() * w;
	const auto px = kRig.project(c);
	return {cv::Point2f(static_cast<float>(px->x), static_cast<float>(px->y)),
		cv::Vec3f(static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2]))};
}

geometry::Pose moved(double x, double z, double yaw_deg = 0)
{
	geometry::Pose p;
	const double a = yaw_deg * CV_PI / 180;
	p.r = cv::Matx33d(std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a));
	p.t = cv::Vec3d(x, 0, z);
	return p;
}

} // namespace

TEST(Keyframes, CovisibilityCountsThePointsBothFramesSaw)
{
	// The keyframe at the origin saw 6 static points; the camera then moved 0.3 m forward and turned 4 deg.
	// It sees 4 of them again and 4 new ones (and one point at the place of an old one but 30 % nearer: a
	// different point). mu = 4 / 9 by hand.
	const std::vector<cv::Vec3d> old_points = {{-1, 0, 5},	  {1, 0.5, 6}, {0, -0.5, 4},
						   {0.5, 0.2, 8}, {-2, 1, 9},  {2, -1, 7}};
	const geometry::Pose origin;
	std::vector<StaticObservation> at_keyframe;
	for (const auto &w : old_points)
		at_keyframe.push_back(observe(origin, w));
	const Keyframe keyframe = make_keyframe(7, origin, at_keyframe);
	ASSERT_EQ(keyframe.static_world.size(), 6U);

	const geometry::Pose now = moved(0.05, 0.3, 4);
	std::vector<StaticObservation> current;
	for (size_t i = 0; i < 4; ++i)
		current.push_back(observe(now, old_points[i]));
	for (const cv::Vec3d &w :
	     {cv::Vec3d(-1.5, 0.3, 6), cv::Vec3d(1.5, -0.3, 5), cv::Vec3d(0.3, 0.9, 7), cv::Vec3d(-0.7, -0.8, 4)})
		current.push_back(observe(now, w));
	StaticObservation nearer = observe(now, old_points[4]);
	nearer.xyz *= 0.7F; // same pixel, another depth
	current.push_back(nearer);
	KeyframeParams params;
	EXPECT_NEAR(covisibility(current, now, keyframe, kRig, params), 4.0 / 9.0, 1e-12);
	// A wrong pose for this frame puts the keyframe's points elsewhere: nothing is shared.
	EXPECT_EQ(covisibility(current, moved(0.8, 0.3, 4), keyframe, kRig, params), 0);
	EXPECT_EQ(covisibility({}, now, keyframe, kRig, params), 0);
}

TEST(Keyframes, ANewKeyframeNeedsMotionAndANewView)
{
	// The keyframe saw 40 points; the frame sees 40 points, `shared` of them the keyframe's.
	const geometry::Pose origin;
	std::vector<StaticObservation> at_keyframe;
	for (int i = 0; i < 40; ++i)
		at_keyframe.push_back(observe(origin, {-2.0 + 0.1 * i, 0.02 * i, 6.0 + 0.05 * i}));
	const Keyframe keyframe = make_keyframe(0, origin, at_keyframe);
	const auto frame = [&](const geometry::Pose &pose, int shared) {
		std::vector<StaticObservation> seen;
		for (int i = 0; i < 40; ++i)
			seen.push_back(i < shared ? observe(pose, {-2.0 + 0.1 * i, 0.02 * i, 6.0 + 0.05 * i})
						  : observe(pose, {-2.0 + 0.1 * i, 1.5 - 0.02 * i, 3.0 + 0.1 * i}));
		return seen;
	};
	KeyframeParams params; // 0.1 m or 5 deg; mu < 0.7; 15 new points
	// Moved 0.2 m, 10 of 40 shared (mu 0.25, 30 new): a keyframe.
	auto d = decide_keyframe(keyframe, moved(0, 0.2), frame(moved(0, 0.2), 10), kRig, params);
	EXPECT_TRUE(d.moved);
	EXPECT_NEAR(d.translation_m, 0.2, 1e-12);
	EXPECT_NEAR(d.covisibility, 0.25, 1e-12);
	EXPECT_EQ(d.new_points, 30);
	EXPECT_TRUE(d.keyframe);
	// The same view, but the camera moved only 5 cm (eq. 6 fails): none.
	d = decide_keyframe(keyframe, moved(0, 0.05), frame(moved(0, 0.05), 10), kRig, params);
	EXPECT_FALSE(d.moved);
	EXPECT_FALSE(d.keyframe);
	// Turned 6 degrees in place: moved by eq. 6's rotation.
	d = decide_keyframe(keyframe, moved(0, 0, 6), frame(moved(0, 0, 6), 10), kRig, params);
	EXPECT_TRUE(d.moved);
	EXPECT_NEAR(d.rotation_deg, 6, 1e-9);
	EXPECT_TRUE(d.keyframe);
	// Moved 0.2 m but back over the same view: 32 of 40 shared (mu 0.8): none.
	d = decide_keyframe(keyframe, moved(0, 0.2), frame(moved(0, 0.2), 32), kRig, params);
	EXPECT_NEAR(d.covisibility, 0.8, 1e-12);
	EXPECT_FALSE(d.keyframe);
	// mu 0.65 is below 0.7 but leaves 14 new points, one short of 15: none.
	d = decide_keyframe(keyframe, moved(0, 0.2), frame(moved(0, 0.2), 26), kRig, params);
	EXPECT_EQ(d.new_points, 14);
	EXPECT_FALSE(d.keyframe);
}
