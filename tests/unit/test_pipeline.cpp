#include <gtest/gtest.h>

#include <mutex>
#include <thread>

#include "core/protocol.hpp"
#include "daemon/pipeline.hpp"

using namespace stereod;
using namespace stereod::daemon;

namespace {

std::unique_ptr<drivers::FrameSource> small_sim(uint64_t frames, bool realtime, double fps = 30)
{
	drivers::SourceConfig config;
	config.realtime = realtime;
	config.sim.width = 320;
	config.sim.height = 240;
	config.sim.frames = frames;
	config.sim.fps = fps;
	config.sim.stereo = false;
	return drivers::SourceRegistry::with_builtin_drivers().create(config);
}

/// The sim's calibrated stereo rig, offline.
std::unique_ptr<drivers::FrameSource> stereo_sim(int width, int height, uint64_t frames)
{
	drivers::SourceConfig config;
	config.realtime = false;
	config.sim.width = width;
	config.sim.height = height;
	config.sim.frames = frames;
	return drivers::SourceRegistry::with_builtin_drivers().create(config);
}

} // namespace

TEST(Pipeline, BlockPublishesEveryFrameInOrder)
{
	std::vector<FrameResult> results;
	PipelineOptions options;
	options.workers = 3;
	options.ring_capacity = 2;
	options.overflow = OverflowPolicy::Block;
	options.motion.features.max_features = 300;
	Pipeline pipeline(small_sim(40, false), options, [&](FrameResult &r) { results.push_back(std::move(r)); });
	pipeline.start();
	pipeline.wait();
	ASSERT_EQ(results.size(), 40U);
	for (size_t i = 0; i < results.size(); ++i) {
		EXPECT_EQ(results[i].seq, i);
		EXPECT_GE(results[i].t_publish_ns, results[i].t_host_ns);
		if (i > 0) {
			EXPECT_FALSE(results[i].points.empty()) << "frame " << i << " pairs with frame " << i - 1;
		}
	}
	EXPECT_TRUE(results[0].points.empty()) << "the first frame has nothing to pair with";
	const auto stats = pipeline.stats();
	EXPECT_EQ(stats.frames_captured, 40U);
	EXPECT_EQ(stats.ring_evicted, 0U);
	EXPECT_EQ(stats.source_state, "finished");
}

TEST(Pipeline, StereoPathMatchesTheRightEyesFeaturesOnHealthFramesOnly)
{
	// The stereo path through the workers: the right eye's features are extracted beside the left's (on
	// another thread) on every 5th frame, and only those frames have descriptor candidates. Under TSan this
	// is the check that the two eyes' extraction shares nothing it should not.
	auto source = stereo_sim(320, 240, 21);
	std::vector<FrameResult> results;
	PipelineOptions options;
	options.workers = 2;
	options.overflow = OverflowPolicy::Block;
	options.motion.features.max_features = 300;
	options.motion.rig = source->info().calibration;
	options.motion.stereo.health_every_frames = 5;
	Pipeline pipeline(std::move(source), options, [&](FrameResult &r) { results.push_back(std::move(r)); });
	pipeline.start();
	pipeline.wait();
	ASSERT_EQ(results.size(), 21U);
	for (size_t i = 0; i < results.size(); ++i) {
		ASSERT_TRUE(results[i].stereo) << "frame " << i;
		EXPECT_GT(results[i].stereo->matched, 50) << "frame " << i;
		if (i % 5 == 0)
			EXPECT_GT(results[i].stereo->candidates, 50) << "health frame " << i;
		else
			EXPECT_EQ(results[i].stereo->candidates, 0) << "frame " << i;
		if (i > 0) {
			ASSERT_TRUE(results[i].ego) << "frame " << i;
			EXPECT_TRUE(results[i].ego->valid) << "frame " << i;
		}
	}
}

TEST(Pipeline, WarmUpLeavesTheResultsAsTheyWere)
{
	// The workers' warm-up runs the stages on made-up frames before capture: nothing of it may reach a
	// result. Stereo sim with depth, the groups and the rescue on: every field but the clocks and the
	// stage times must be the same with and without it.
	const auto messages = [](bool warm_up) {
		auto source = stereo_sim(640, 480, 12);
		PipelineOptions options;
		options.workers = 2;
		options.overflow = OverflowPolicy::Block;
		options.warm_up = warm_up;
		options.motion.features.max_features = 500;
		options.motion.rig = source->info().calibration;
		std::vector<std::string> out;
		Pipeline pipeline(std::move(source), options, [&](FrameResult &r) {
			r.t_host_ns = r.t_publish_ns = 0;
			r.timing.clear();
			out.push_back(protocol::frame_message(r));
		});
		pipeline.start();
		pipeline.wait();
		return out;
	};
	const auto warm = messages(true);
	const auto cold = messages(false);
	ASSERT_EQ(warm.size(), 12U);
	ASSERT_EQ(cold.size(), warm.size());
	size_t with_groups = 0;
	for (size_t i = 0; i < warm.size(); ++i) {
		EXPECT_EQ(warm[i], cold[i]) << "frame " << i;
		with_groups += warm[i].find("\"groups\":[]") == std::string::npos;
	}
	EXPECT_GT(with_groups, 0U) << "the comparison should cover frames with groups";
}

TEST(Pipeline, DropOldestCountsWhatASlowConsumerLoses)
{
	std::vector<uint64_t> published;
	PipelineOptions options;
	options.workers = 1;
	options.ring_capacity = 2;
	options.overflow = OverflowPolicy::DropOldest;
	options.motion.enabled = false;
	// The consumer stalls on its first frame until the source has delivered all 60, so drops are certain
	// however slow the machine (a sanitizer build on a busy CI host renders the sim slower than 15 ms).
	Pipeline *self = nullptr;
	Pipeline pipeline(small_sim(60, true, 200), options, [&](FrameResult &r) {
		if (published.empty()) {
			const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
			while (self->stats().frames_captured < 60 && std::chrono::steady_clock::now() < give_up)
				std::this_thread::sleep_for(std::chrono::milliseconds(2));
		}
		published.push_back(r.seq);
	});
	self = &pipeline;
	pipeline.start();
	pipeline.wait();
	const auto stats = pipeline.stats();
	EXPECT_EQ(stats.frames_captured, 60U);
	EXPECT_GT(stats.ring_evicted + stats.pool_exhausted, 0U);
	EXPECT_EQ(published.size() + stats.ring_evicted + stats.pool_exhausted, 60U)
		<< "every captured frame is either published or counted as dropped";
	for (size_t i = 1; i < published.size(); ++i)
		EXPECT_LT(published[i - 1], published[i]);
}

TEST(Pipeline, StopDrainsWhatWasCaptured)
{
	std::mutex m;
	uint64_t count = 0;
	PipelineOptions options;
	options.workers = 2;
	options.overflow = OverflowPolicy::Block;
	options.motion.features.max_features = 200;
	Pipeline pipeline(small_sim(0, true, 60), options, [&](FrameResult &) {
		std::lock_guard lock(m);
		++count;
	});
	pipeline.start();
	// Stop mid-stream: once a few frames are out (however slow the build), with more on their way.
	const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
	for (;;) {
		{
			std::lock_guard lock(m);
			if (count > 5 || std::chrono::steady_clock::now() > give_up)
				break;
		}
		std::this_thread::sleep_for(std::chrono::milliseconds(5));
	}
	pipeline.request_stop();
	pipeline.wait();
	EXPECT_EQ(count, pipeline.stats().frames_captured) << "nothing captured is lost on stop";
	EXPECT_GT(count, 5U);
	EXPECT_EQ(pipeline.stats().source_state, "stopped");
}

// ------------------------------------------------------------------------------------------ watchdog
#include "daemon/watchdog.hpp"

TEST(Watchdog, PingsOnlyWhileFramesGetThrough)
{
	using stereod::daemon::pipeline_alive;
	using stereod::daemon::WatchdogSample;
	constexpr int64_t kNow = 10'000'000'000, kLimit = 2'000'000'000;
	const WatchdogSample before{100, 95, kNow - 50'000'000};
	// Frames in and out: alive.
	EXPECT_TRUE(pipeline_alive(before, {110, 104, kNow - 10'000'000}, kNow, kLimit));
	// Nothing in (a camera away, the source reconnecting): not the pipeline's fault, alive.
	EXPECT_TRUE(pipeline_alive(before, {100, 95, kNow - 10'000'000}, kNow, kLimit));
	// Frames in, none out: a hung stage.
	EXPECT_FALSE(pipeline_alive(before, {110, 95, kNow - 10'000'000}, kNow, kLimit));
	// The capture loop stopped turning (a driver call that never returns), whatever the counters say.
	EXPECT_FALSE(pipeline_alive(before, {100, 95, kNow - 3'000'000'000}, kNow, kLimit));
}
