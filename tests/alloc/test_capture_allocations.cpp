// The capture path allocates nothing in steady state (FrameSource::grab's contract, the design card's "no
// allocation on the capture path"): every heap allocation of the process is counted here (malloc_counter.hpp)
// while a source grabs into a pool frame that then goes through the ring,
// as Pipeline::capture_loop does. A source's first frames may allocate (lazily sized buffers); the frames
// after them must not, but for one: a one-off such as a thread of OpenCV's or Aravis's starting late is not
// the per-frame allocation this is after, which shows in every frame or every few (the V4L2 bed saw such a
// one-off; docs/architecture.md). Each counted frame is counted on its own.
#include <gtest/gtest.h>

#include <filesystem>
#include <unistd.h>

#include "core/frame_pool.hpp"
#include "core/spsc_ring.hpp"
#include "drivers/camera_frames.hpp"
#include "drivers/replay/recording.hpp"
#include "drivers/source.hpp"
#include "tests/alloc/malloc_counter.hpp"

#include <arv.h>

using stereod::test::allocations_during;
using stereod::test::FrameAllocations;

using namespace stereod;

namespace {

/// What Pipeline::capture_loop does with one frame: a pool slot, the source's grab into it, the slot's index
/// through the ring, and the consumer's adopting it and giving it back.
class CaptureLoop
{
public:
	CaptureLoop(drivers::FrameSource &source, size_t pool_size)
		: source_(source), pool_(pool_size, source.info().geometry), ring_(4, OverflowPolicy::DropOldest)
	{
	}

	/// Grabs `frames` frames; false when the source could not deliver them all.
	bool run(int frames)
	{
		for (int i = 0; i < frames; ++i)
			if (!one())
				return false;
		return true;
	}

	/// Grabs `frames` frames counting each one's allocations; `delivered` false when the source could not
	/// deliver them all.
	FrameAllocations counted(int frames)
	{
		FrameAllocations out;
		for (int i = 0; i < frames; ++i) {
			bool ok = false;
			out.add(allocations_during([&] { ok = one(); }));
			if (!ok) {
				out.delivered = false;
				break;
			}
		}
		return out;
	}

private:
	bool one()
	{
		std::optional<FrameHandle> frame = pool_.try_acquire();
		if (!frame || source_.grab(**frame) != drivers::GrabStatus::Frame)
			return false;
		uint32_t evicted = 0;
		if (ring_.push(frame->release(), evicted) == SpscRing<uint32_t>::PushResult::PushedEvicted)
			pool_.adopt(evicted).reset();
		if (auto index = ring_.try_pop())
			pool_.adopt(*index).reset();
		return true;
	}

	drivers::FrameSource &source_;
	FramePool pool_;
	SpscRing<uint32_t> ring_;
};

constexpr int kWarmUpFrames = 5;
constexpr int kCountedFrames = 30;

} // namespace

TEST(CaptureAllocations, TheCounterSeesAnAllocation)
{
	// The checks below would pass vacuously if the interposition were not in effect: an image buffer
	// (OpenCV's allocator, malloc) and a C++ object (operator new) are both seen.
	cv::Mat image;
	EXPECT_GE(allocations_during([&] { image.create(480, 640, CV_8UC3); }), 1U);
	std::unique_ptr<std::vector<int>> vector;
	EXPECT_GE(allocations_during([&] { vector = std::make_unique<std::vector<int>>(100); }), 1U);
}

TEST(CaptureAllocations, PoolAndRing)
{
	FramePool pool(4, {64, 48, PixelFormat::Bgr8, true, false, false, 30});
	SpscRing<uint32_t> ring(2, OverflowPolicy::DropOldest);
	const uint64_t n = allocations_during([&] {
		for (int i = 0; i < 1000; ++i) {
			std::optional<FrameHandle> frame = pool.try_acquire();
			ASSERT_TRUE(frame);
			uint32_t evicted = 0;
			if (ring.push(frame->release(), evicted) == SpscRing<uint32_t>::PushResult::PushedEvicted)
				pool.adopt(evicted).reset();
			if (i % 3 == 0)
				if (auto index = ring.try_pop())
					pool.adopt(*index).reset();
		}
	});
	EXPECT_EQ(n, 0U);
}

namespace {

/// Records frames of the sim into `path` (.srec or .mcap by its extension), then replays it through the
/// capture loop: the allocations of the frames after the warm-up.
FrameAllocations replay_allocations(const std::string &path)
{
	drivers::SourceConfig config;
	config.realtime = false;
	config.sim.width = 320;
	config.sim.height = 240;
	{
		const auto sim = drivers::SourceRegistry::with_builtin_drivers().create(config);
		StereoFrame frame;
		frame.allocate(sim->info().geometry);
		const auto recorder = drivers::open_recorder(path, {"sim", "allocation test", sim->info().geometry, 0});
		for (int i = 0; i < kWarmUpFrames + kCountedFrames; ++i) {
			EXPECT_EQ(sim->grab(frame), drivers::GrabStatus::Frame);
			recorder->append(frame);
		}
	}
	config.driver = "replay";
	config.path = path;
	config.rate = drivers::ReplayRate::Fast;
	const auto source = drivers::SourceRegistry::with_builtin_drivers().create(config);
	CaptureLoop loop(*source, 4);
	EXPECT_TRUE(loop.run(kWarmUpFrames));
	const FrameAllocations a = loop.counted(kCountedFrames);
	EXPECT_TRUE(a.delivered) << path;
	return a;
}

std::string temporary_path(const char *extension)
{
	return (std::filesystem::temp_directory_path() / ("stereod-alloc-" + std::to_string(getpid()) + extension))
		.string();
}

} // namespace

TEST(CaptureAllocations, ReplayOfAnSrecRecording)
{
	const std::string path = temporary_path(".srec");
	const FrameAllocations a = replay_allocations(path);
	EXPECT_TRUE(a.steady()) << a;
	std::filesystem::remove(path);
}

TEST(CaptureAllocations, ReplayOfAnMcapRecording)
{
	const std::string path = temporary_path(".mcap");
	const FrameAllocations a = replay_allocations(path);
	EXPECT_TRUE(a.steady()) << a;
	std::filesystem::remove(path);
}

namespace {

/// The pixel work every camera driver (Aravis, V4L2, dc1394) does per buffer, for one recipe.
FrameAllocations fill_eyes_allocations(const drivers::PixelRecipe &recipe, int width, int height)
{
	const cv::Size eye = camera::eye_size(recipe.layout, width, height);
	std::vector<uint8_t> buffer(static_cast<size_t>(width) * height * recipe.bytes_per_pixel);
	for (size_t i = 0; i < buffer.size(); ++i)
		buffer[i] = static_cast<uint8_t>(i * 31 + i / 7);
	drivers::EyeScratch scratch;
	scratch.allocate(eye);
	const int type = recipe.output == PixelFormat::Bgr8 ? CV_8UC3 : CV_8UC1;
	cv::Mat left(eye, type), right(eye, type);
	cv::Mat *right_eye = recipe.layout == camera::StereoLayout::Pair ? nullptr : &right;
	for (int i = 0; i < kWarmUpFrames; ++i)
		drivers::fill_eyes(recipe, buffer.data(), buffer.size(), width, height, scratch, left, right_eye);
	FrameAllocations a;
	for (int i = 0; i < kCountedFrames; ++i)
		a.add(allocations_during([&] {
			drivers::fill_eyes(recipe, buffer.data(), buffer.size(), width, height, scratch, left,
					   right_eye);
		}));
	return a;
}

} // namespace

TEST(CaptureAllocations, CameraPixelsForEveryLayout)
{
	using camera::Mosaic;
	using camera::StereoLayout;
	struct Case {
		const char *name;
		drivers::PixelRecipe recipe;
	};
	const Case cases[] = {
		{"pair, Mono8", {StereoLayout::Pair, 1, false, false, Mosaic::None, PixelFormat::Mono8}},
		{"pair, RGB8", {StereoLayout::Pair, 3, true, false, Mosaic::None, PixelFormat::Bgr8}},
		{"pair, BayerRG8 to BGR", {StereoLayout::Pair, 1, false, false, Mosaic::RGGB, PixelFormat::Bgr8}},
		{"pair, Mono16 (high bytes)", {StereoLayout::Pair, 2, false, false, Mosaic::None, PixelFormat::Mono8}},
		{"interleaved16 (Bumblebee), mono",
		 {StereoLayout::Interleaved16, 2, false, false, Mosaic::None, PixelFormat::Mono8}},
		{"interleaved16 (Bumblebee), Bayer to BGR",
		 {StereoLayout::Interleaved16, 2, false, false, Mosaic::GRBG, PixelFormat::Bgr8}},
		{"side by side, Mono8", {StereoLayout::SideBySide, 1, false, false, Mosaic::None, PixelFormat::Mono8}},
		{"top bottom, Bayer to BGR",
		 {StereoLayout::TopBottom, 1, false, false, Mosaic::BGGR, PixelFormat::Bgr8}},
	};
	for (const Case &c : cases) {
		const FrameAllocations a = fill_eyes_allocations(c.recipe, 640, 480);
		EXPECT_TRUE(a.steady()) << c.name << ": " << a;
	}
}

TEST(CaptureAllocations, AravisWithItsInProcessFakeCamera)
{
	// Aravis's own fake device (the "Fake" interface: a GenICam camera simulated inside this process, no
	// network), through the same driver as a GigE or USB3 camera: buffers popped from the stream, the frame
	// filled, the buffer pushed back.
	// The real interfaces off: opening a device by name must not send GigE discovery out of this machine.
	arv_disable_interface("GigEVision");
	arv_disable_interface("USB3Vision");
	arv_enable_interface("Fake");
	drivers::SourceConfig config;
	config.driver = "aravis";
	config.aravis.left = "Fake_1";
	config.aravis.layout = "side_by_side";
	config.aravis.frame_rate = 100;
	const auto source = drivers::SourceRegistry::with_builtin_drivers().create(config);
	CaptureLoop loop(*source, 4);
	ASSERT_TRUE(loop.run(kWarmUpFrames));
	const FrameAllocations a = loop.counted(kCountedFrames);
	EXPECT_TRUE(a.delivered);
	EXPECT_TRUE(a.steady()) << a;
}
