#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "drivers/sim/sim_scene.hpp"
#include "drivers/source.hpp"

using namespace stereod;
using namespace stereod::drivers;

namespace {

std::unique_ptr<FrameSource> make_sim(uint64_t seed, const std::string &scene = "default", bool depth = false)
{
	SourceConfig config;
	config.driver = "sim";
	config.realtime = false;
	config.sim.seed = seed;
	config.sim.scene = scene;
	config.sim.width = 320;
	config.sim.height = 240;
	config.sim.depth = depth;
	return SourceRegistry::with_builtin_drivers().create(config);
}

StereoFrame grab_nth(FrameSource &source, int n)
{
	StereoFrame frame;
	frame.allocate(source.info().geometry);
	for (int i = 0; i <= n; ++i)
		EXPECT_EQ(source.grab(frame), GrabStatus::Frame);
	return frame;
}

} // namespace

TEST(Sim, SameSeedSameFramesOtherSeedOtherFrames)
{
	auto a = make_sim(7), b = make_sim(7), c = make_sim(8);
	const StereoFrame fa = grab_nth(*a, 5), fb = grab_nth(*b, 5), fc = grab_nth(*c, 5);
	EXPECT_EQ(cv::norm(fa.left, fb.left, cv::NORM_INF), 0.0);
	EXPECT_GT(cv::norm(fa.left, fc.left, cv::NORM_L1), 0.0);
	EXPECT_EQ(fa.sequence, 5U);
	EXPECT_EQ(fa.device_ns, 166'666'667);
}

TEST(Sim, FillsBuffersInPlace)
{
	auto sim = make_sim(1);
	StereoFrame frame;
	frame.allocate(sim->info().geometry);
	const uchar *left = frame.left.data, *right = frame.right.data, *ids = frame.truth.object_ids.data;
	for (int i = 0; i < 3; ++i)
		ASSERT_EQ(sim->grab(frame), GrabStatus::Frame);
	EXPECT_EQ(frame.left.data, left);
	EXPECT_EQ(frame.right.data, right);
	EXPECT_EQ(frame.truth.object_ids.data, ids);
}

TEST(Sim, TruthMaskMatchesTheMoversProjection)
{
	auto sim = make_sim(1, "static_far");
	const StereoFrame frame = grab_nth(*sim, 40);
	ASSERT_GT(frame.truth.object_count, 0U);
	const double f = 0.9 * 320, cx = 159.5, cy = 119.5;
	int checked = 0;
	for (size_t i = 0; i < frame.truth.object_count; ++i) {
		const auto &o = frame.truth.objects[i];
		const double u = f * o.position_m[0] / o.position_m[2] + cx;
		const double v = f * o.position_m[1] / o.position_m[2] + cy;
		if (u < 0 || v < 0 || u >= 320 || v >= 240)
			continue;
		EXPECT_EQ(frame.truth.object_ids.at<uint8_t>(cvRound(v), cvRound(u)), o.id) << "object " << o.id;
		++checked;
	}
	EXPECT_GT(checked, 0);
}

TEST(Sim, RightEyeDisparityMatchesTrueDepth)
{
	auto sim = make_sim(1, "static_near", true);
	const StereoFrame frame = grab_nth(*sim, 0);
	const double f = 0.9 * 320, baseline = 0.12;
	int checked = 0;
	for (const cv::Point p : {cv::Point(250, 60), cv::Point(270, 200), cv::Point(60, 210)}) {
		const float z = frame.depth.at<float>(p);
		ASSERT_GT(z, 0.0F);
		const double disparity = f * baseline / z;
		const cv::Rect patch(p.x - 6, p.y - 6, 13, 13);
		cv::Mat grey_left, grey_right, score;
		cv::cvtColor(frame.left(patch), grey_left, cv::COLOR_BGR2GRAY);
		const cv::Rect strip(p.x - 60, p.y - 6, 73, 13);
		cv::cvtColor(frame.right(strip), grey_right, cv::COLOR_BGR2GRAY);
		cv::matchTemplate(grey_right, grey_left, score, cv::TM_CCOEFF_NORMED);
		cv::Point best;
		cv::minMaxLoc(score, nullptr, nullptr, nullptr, &best);
		const double found = (p.x - 6) - (strip.x + best.x);
		EXPECT_NEAR(found, disparity, 1.0) << "at " << p << " depth " << z;
		++checked;
	}
	EXPECT_EQ(checked, 3);
}

TEST(Sim, EndsAfterTheConfiguredFrames)
{
	SourceConfig config;
	config.realtime = false;
	config.sim.width = 128;
	config.sim.height = 96;
	config.sim.frames = 3;
	auto sim = SourceRegistry::with_builtin_drivers().create(config);
	StereoFrame frame;
	frame.allocate(sim->info().geometry);
	for (int i = 0; i < 3; ++i)
		EXPECT_EQ(sim->grab(frame), GrabStatus::Frame);
	EXPECT_EQ(sim->grab(frame), GrabStatus::EndOfStream);
}

TEST(Sim, UnknownSceneIsAClearError)
{
	SourceConfig config;
	config.sim.scene = "moon";
	EXPECT_THROW(SourceRegistry::with_builtin_drivers().create(config), SourceError);
}
