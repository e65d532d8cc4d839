// The camera path's pure pieces, on constructed data with known answers: de-interleaving, demosaicing,
// splitting, the device-clock fit, frame-id unwrapping, cadence, pairing, cycle time, the MJPG-free fill.
#include <gtest/gtest.h>

#include <random>

#include <opencv2/imgproc.hpp>

#include "core/camera/layout.hpp"
#include "core/camera/timing.hpp"
#include "drivers/camera_frames.hpp"

using namespace stereod;
using namespace stereod::camera;

TEST(CameraLayout, DeinterleaveSplitsAlternateBytesExactly)
{
	const int w = 37, h = 11; // odd sizes: no assumption of vector-friendly widths
	const size_t stride = 2 * w + 6;
	std::vector<uint8_t> raw(stride * h, 0xEE);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x) {
			raw[static_cast<size_t>(y) * stride + 2 * x] = static_cast<uint8_t>(x + 3 * y);
			raw[static_cast<size_t>(y) * stride + 2 * x + 1] = static_cast<uint8_t>(200 - x - y);
		}
	cv::Mat first(h, w, CV_8UC1), second(h, w, CV_8UC1);
	deinterleave16(raw.data(), w, h, stride, first, second);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x) {
			ASSERT_EQ(first.at<uint8_t>(y, x), static_cast<uint8_t>(x + 3 * y));
			ASSERT_EQ(second.at<uint8_t>(y, x), static_cast<uint8_t>(200 - x - y));
		}
}

TEST(CameraLayout, DeinterleaveRefusesUnallocatedOutputs)
{
	std::vector<uint8_t> raw(16);
	cv::Mat first, second;
	EXPECT_THROW(deinterleave16(raw.data(), 4, 2, 8, first, second), std::invalid_argument);
}

TEST(CameraLayout, SplitViewsSideBySideAndTopBottom)
{
	cv::Mat image(4, 8, CV_8UC1);
	for (int y = 0; y < 4; ++y)
		for (int x = 0; x < 8; ++x)
			image.at<uint8_t>(y, x) = static_cast<uint8_t>(10 * y + x);
	const auto [l, r] = split_views(image, StereoLayout::SideBySide);
	EXPECT_EQ(l.size(), cv::Size(4, 4));
	EXPECT_EQ(r.at<uint8_t>(2, 1), 10 * 2 + 5);
	const auto [t, b] = split_views(image, StereoLayout::TopBottom);
	EXPECT_EQ(t.size(), cv::Size(8, 2));
	EXPECT_EQ(b.at<uint8_t>(0, 3), 20 + 3);
	EXPECT_EQ(eye_size(StereoLayout::SideBySide, 1280, 480), cv::Size(640, 480));
}

TEST(CameraLayout, DemosaicRecoversAFlatColourFromEveryPattern)
{
	// A flat colour seen through each Bayer pattern: every pixel of the developed image is that colour.
	const cv::Vec3b bgr(40, 120, 210);
	for (Mosaic mosaic : {Mosaic::RGGB, Mosaic::GRBG, Mosaic::GBRG, Mosaic::BGGR}) {
		// Pattern letters for the 2x2 tile, row-major.
		const char *tile = mosaic == Mosaic::RGGB   ? "RGGB"
				   : mosaic == Mosaic::GRBG ? "GRBG"
				   : mosaic == Mosaic::GBRG ? "GBRG"
							    : "BGGR";
		cv::Mat raw(16, 16, CV_8UC1);
		for (int y = 0; y < 16; ++y)
			for (int x = 0; x < 16; ++x) {
				const char c = tile[(y % 2) * 2 + x % 2];
				raw.at<uint8_t>(y, x) = c == 'B' ? bgr[0] : c == 'G' ? bgr[1] : bgr[2];
			}
		cv::Mat out(16, 16, CV_8UC3);
		const void *before = out.data;
		develop(raw, mosaic, PixelFormat::Bgr8, out);
		EXPECT_EQ(out.data, before) << "reallocated";
		const cv::Vec3b centre = out.at<cv::Vec3b>(8, 8);
		EXPECT_EQ(centre, bgr) << tile;
	}
}

TEST(CameraLayout, MonoDevelopIsACopyAndHighBytesTakesTheTopByte)
{
	cv::Mat raw(3, 5, CV_8UC1, cv::Scalar(77));
	cv::Mat out(3, 5, CV_8UC1);
	develop(raw, Mosaic::None, PixelFormat::Mono8, out);
	EXPECT_EQ(cv::countNonZero(out != 77), 0);
	const uint16_t samples[4] = {0x1234, 0xABCD, 0x00FF, 0xFF00};
	cv::Mat high(1, 4, CV_8UC1);
	high_bytes(reinterpret_cast<const uint8_t *>(samples), 4, 1, 8, high);
	EXPECT_EQ(high.at<uint8_t>(0, 0), 0x12);
	EXPECT_EQ(high.at<uint8_t>(0, 1), 0xAB);
	EXPECT_EQ(high.at<uint8_t>(0, 2), 0x00);
	EXPECT_EQ(high.at<uint8_t>(0, 3), 0xFF);
}

TEST(CameraFrames, FillEyesInterleavedPutsEachByteInItsEye)
{
	drivers::PixelRecipe recipe;
	recipe.layout = StereoLayout::Interleaved16;
	recipe.bytes_per_pixel = 2;
	recipe.first_is_left = false; // Bumblebee: byte 0 is the right eye
	const int w = 6, h = 4;
	std::vector<uint8_t> raw(static_cast<size_t>(w * h * 2));
	for (size_t i = 0; i < raw.size(); i += 2) {
		raw[i] = 11;	 // right
		raw[i + 1] = 22; // left
	}
	drivers::EyeScratch scratch;
	scratch.allocate({w, h});
	cv::Mat left(h, w, CV_8UC1), right(h, w, CV_8UC1);
	drivers::fill_eyes(recipe, raw.data(), raw.size(), w, h, scratch, left, &right);
	EXPECT_EQ(cv::countNonZero(left != 22), 0);
	EXPECT_EQ(cv::countNonZero(right != 11), 0);
	EXPECT_THROW(drivers::fill_eyes(recipe, raw.data(), raw.size() - 1, w, h, scratch, left, &right),
		     std::runtime_error);
}

TEST(DeviceClock, RecoversOffsetAndDriftUnderPositiveJitter)
{
	// A device clock 80 ppm fast with an arbitrary epoch; deliveries take 1 ms plus exponential jitter
	// (mean 2 ms) with occasional 40 ms stalls. The mapping must land within 0.1 ms of device time + 1 ms.
	std::mt19937_64 rng(7);
	std::exponential_distribution<double> jitter(1.0 / 2e6);
	std::uniform_real_distribution<double> u(0, 1);
	const double drift = 80e-6;
	const int64_t device0 = 1'796'000'000'000'000'000, host0 = 5'000'000'000;
	DeviceClock clock;
	double worst_late = 0;
	for (int i = 0; i < 30 * 60; ++i) { // one minute at 30 fps
		const int64_t device = device0 + static_cast<int64_t>(i) * 33'333'333;
		const double true_host =
			static_cast<double>(host0) + static_cast<double>(device - device0) / (1 + drift);
		double delay = 1e6 + jitter(rng);
		if (u(rng) < 0.01)
			delay += 40e6;
		ASSERT_TRUE(clock.add(device, static_cast<int64_t>(true_host + delay)));
		if (i > 30 * 15) { // after the first 15 s
			const double error = static_cast<double>(clock.to_host(device)) - (true_host + 1e6);
			worst_late = std::max(worst_late, std::abs(error));
		}
	}
	EXPECT_NEAR(clock.drift(), -drift / (1 + drift), 5e-6);
	EXPECT_LT(worst_late, 1e5) << "mapped time off by " << worst_late << " ns";
}

TEST(DeviceClock, RestartsWhenTheDeviceClockJumps)
{
	DeviceClock clock;
	for (int i = 0; i < 10; ++i)
		ASSERT_TRUE(clock.add(1'000'000'000 + i * 10'000'000, 50'000'000'000 + i * 10'000'000));
	EXPECT_FALSE(clock.add(5'000, 50'200'000'000)); // camera reset: its clock starts again near 0
	EXPECT_EQ(clock.restarts(), 1U);
	EXPECT_EQ(clock.to_host(5'000), 50'200'000'000);
}

TEST(FrameIdCounter, SixteenBitBlockIdsWrapToOneWithoutAGap)
{
	FrameIdCounter ids(16, true);
	uint64_t missing = 0;
	for (uint64_t id : {65533, 65534, 65535, 1, 2})
		missing += ids.add(id);
	EXPECT_EQ(missing, 0U);
	EXPECT_EQ(ids.unwrapped(), 4U);
	EXPECT_EQ(ids.add(5), 2U); // 3 and 4 lost
	EXPECT_EQ(ids.add(65534 + 5 - 65535 + 0), 0U) << "an older id is not a gap";
	EXPECT_EQ(ids.add(65535), 0U) << "nor is one from far behind";
	EXPECT_EQ(ids.missing(), 2U);
	FrameIdCounter across(16, true);
	across.add(65534);
	EXPECT_EQ(across.add(2), 2U) << "65535 and 1 are missing (0 is never used)";
}

TEST(FrameIdCounter, ThirtyTwoBitSequencesCountZero)
{
	FrameIdCounter seq(32, false);
	seq.add(4294967294U);
	EXPECT_EQ(seq.add(4294967295U), 0U);
	EXPECT_EQ(seq.add(0), 0U);
	EXPECT_EQ(seq.add(3), 2U);
}

TEST(Outage, CountsThePeriodsBetweenTheLastFrameBeforeAndTheFirstAfter)
{
	constexpr int64_t kPeriod = 33'333'333; // 30 fps
	OutageCounter outage(30);
	for (int64_t i = 0; i < 10; ++i)
		outage.delivered(i * kPeriod);
	EXPECT_EQ(outage.lost(), 0U) << "no outage yet";
	outage.delivered(15 * kPeriod);
	EXPECT_EQ(outage.lost(), 0U) << "a gap without a reconnect is the frame counters' to count, not this";
	outage.reconnected();
	outage.delivered(15 * kPeriod + 500'000'000 + 2'000'000); // 0.5 s later, 2 ms of jitter
	EXPECT_EQ(outage.lost(), 14U) << "15 periods, 14 frames never sent";
	outage.delivered(16 * kPeriod + 500'000'000);
	EXPECT_EQ(outage.lost(), 14U) << "the outage ended with the first frame after it";
	outage.reconnected();
	outage.delivered(17 * kPeriod + 500'000'000);
	EXPECT_EQ(outage.lost(), 14U) << "reopened with no frame lost";
	OutageCounter before_any(30);
	before_any.reconnected();
	before_any.delivered(5 * kPeriod);
	EXPECT_EQ(before_any.lost(), 0U) << "nothing to measure from before the first frame";
	OutageCounter no_rate;
	no_rate.delivered(0);
	no_rate.reconnected();
	no_rate.delivered(10 * kPeriod);
	EXPECT_EQ(no_rate.lost(), 0U) << "without a nominal rate nothing can be said";
}

TEST(Cadence, CountsSkippedPeriodsAndIrregularIntervals)
{
	const int64_t period = 33'333'333;
	CadenceTracker cadence(period, 2'000'000);
	int64_t t = 1'796'000'000'000'000'000;
	cadence.add(t);
	cadence.add(t += 20'000'000); // the first frame after start is off the cadence
	EXPECT_EQ(cadence.irregular_intervals(), 1U);
	for (int i = 0; i < 100; ++i)
		cadence.add(t += period + (i % 3) * 300'000 - 300'000); // on time, sub-ms jitter
	EXPECT_EQ(cadence.skipped_periods(), 0U);
	EXPECT_EQ(cadence.irregular_intervals(), 1U) << "one early frame must not make every later one late";
	cadence.add(t += 3 * period); // two periods with no frame
	EXPECT_EQ(cadence.skipped_periods(), 2U);
	cadence.add(t += period + 9'000'000); // 9 ms late
	cadence.add(t += period - 9'000'000); // back on the cadence
	cadence.add(t += period);
	EXPECT_EQ(cadence.irregular_intervals(), 3U);
	EXPECT_EQ(cadence.skipped_periods(), 2U);
}

TEST(Pairing, PairsWithinTheSkewAndDropsTheOlderOtherwise)
{
	EXPECT_EQ(pair_action(1000, 2500, 2000), PairAction::Pair);
	EXPECT_EQ(pair_action(1000, 3500, 2000), PairAction::DropLeft);
	EXPECT_EQ(pair_action(3500, 1000, 2000), PairAction::DropRight);
}

TEST(CycleTime, DecodesAndUnwrapsThe128SecondPeriod)
{
	// 3 s, 4000 cycles (0.5 s), offset 1536 (half a cycle, 62.5 us)
	const uint32_t stamp = (3U << 25) | (4000U << 12) | 1536U;
	EXPECT_EQ(CycleTimeClock::decode(stamp), 3'500'062'500);
	CycleTimeClock clock;
	EXPECT_EQ(clock.unwrap((127U << 25) | (7999U << 12)), 127'999'875'000);
	EXPECT_EQ(clock.unwrap(1U << 25), 128'000'000'000 + 1'000'000'000);
}
