#include <gtest/gtest.h>

#include <sys/resource.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "daemon/live_recorder.hpp"
#include "drivers/replay/recording.hpp"

using namespace stereod;
using namespace stereod::drivers;
namespace fs = std::filesystem;

namespace {

FrameGeometry geometry()
{
	return {32, 24, PixelFormat::Bgr8, true, false, true, 30};
}

void fill(StereoFrame &f, uint64_t i)
{
	f.sequence = i;
	f.device_ns = static_cast<int64_t>(i) * 33'333'333;
	f.host_ns = 1000 + static_cast<int64_t>(i);
	f.lr_skew_ns = static_cast<int64_t>(i % 3);
	f.status = i == 2 ? FrameStatus::Incomplete : FrameStatus::Ok;
	f.left.setTo(cv::Scalar(static_cast<double>(i), 1, 2));
	f.right.setTo(cv::Scalar(3, static_cast<double>(i), 4));
	f.truth.object_ids.setTo(static_cast<double>(i % 5));
	f.truth.object_count = 1;
	f.truth.objects[0] = {9, {1.0, 2.0, static_cast<double>(i)}, {0.5, 0, 0}};
}

class RecordingTest : public ::testing::Test
{
protected:
	void SetUp() override
	{
		path_ = (fs::temp_directory_path() / ("stereod-rec-" + std::to_string(::getpid()) + ".srec")).string();
		StereoFrame frame;
		frame.allocate(geometry());
		RecordingWriter writer(path_, {"sim", "test", geometry(), 0});
		for (uint64_t i = 0; i < 5; ++i) {
			fill(frame, i);
			writer.append(frame);
			sizes_.push_back(writer.bytes_written());
		}
	}
	void TearDown() override { fs::remove(path_); }

	uint64_t read_all(RecordingReader &reader)
	{
		StereoFrame frame;
		frame.allocate(reader.header().geometry);
		uint64_t n = 0;
		while (reader.next(frame))
			++n;
		return n;
	}

	std::string path_;
	std::vector<uint64_t> sizes_; ///< file size after each frame
};

} // namespace

TEST_F(RecordingTest, ReadsBackExactly)
{
	RecordingReader reader(path_);
	EXPECT_EQ(reader.header().source, "sim");
	EXPECT_EQ(reader.header().geometry, geometry());
	StereoFrame frame, expected;
	frame.allocate(geometry());
	expected.allocate(geometry());
	for (uint64_t i = 0; i < 5; ++i) {
		ASSERT_TRUE(reader.next(frame));
		fill(expected, i);
		EXPECT_EQ(frame.sequence, i);
		EXPECT_EQ(frame.device_ns, expected.device_ns);
		EXPECT_EQ(frame.lr_skew_ns, expected.lr_skew_ns);
		EXPECT_EQ(frame.status, expected.status);
		EXPECT_EQ(cv::norm(frame.left, expected.left, cv::NORM_INF), 0.0);
		EXPECT_EQ(cv::norm(frame.right, expected.right, cv::NORM_INF), 0.0);
		EXPECT_EQ(cv::norm(frame.truth.object_ids, expected.truth.object_ids, cv::NORM_INF), 0.0);
		ASSERT_EQ(frame.truth.object_count, 1U);
		EXPECT_DOUBLE_EQ(frame.truth.objects[0].position_m[2], static_cast<double>(i));
	}
	EXPECT_FALSE(reader.next(frame));
	EXPECT_TRUE(reader.report().clean_end);
	EXPECT_EQ(reader.report().frames, 5U);
}

TEST_F(RecordingTest, TruncationAnywhereKeepsEveryCompleteFrame)
{
	// Cut inside the 4th record at several points, including inside its 12-byte record header.
	for (uint64_t cut : {sizes_[2] + 1, sizes_[2] + 11, sizes_[2] + 100, sizes_[3] - 1}) {
		fs::resize_file(path_, cut);
		RecordingReader reader(path_);
		EXPECT_EQ(read_all(reader), 3U) << "cut at " << cut;
		EXPECT_FALSE(reader.report().clean_end);
		EXPECT_EQ(reader.report().cut_at_offset, sizes_[2]);
		EXPECT_EQ(reader.report().bytes_dropped, cut - sizes_[2]);
		EXPECT_NE(reader.report().describe().find("3 complete frames recovered"), std::string::npos);
	}
}

// Found by fuzz_recording (out of memory): a record claiming more bytes than the file has left was allocated
// before being read. It is a cut, said before any allocation.
TEST_F(RecordingTest, ARecordLongerThanTheFileIsACutNotAnAllocation)
{
	{
		std::fstream f(path_, std::ios::in | std::ios::out | std::ios::binary);
		f.seekp(static_cast<std::streamoff>(sizes_[1] + 4)); // the 3rd record's length field
		const uint32_t huge = 900U << 20;		     // 900 MB, under the format's 1 GB limit
		f.write(reinterpret_cast<const char *>(&huge), sizeof(huge));
	}
	const auto peak_kb = [] {
		rusage usage{};
		getrusage(RUSAGE_SELF, &usage);
		return usage.ru_maxrss;
	};
	const long before = peak_kb();
	RecordingReader reader(path_);
	EXPECT_EQ(read_all(reader), 2U);
	EXPECT_EQ(reader.report().cut_at_offset, sizes_[1]);
	EXPECT_NE(reader.report().reason.find("record cut short"), std::string::npos) << reader.report().reason;
	EXPECT_LT(peak_kb() - before, 100 * 1024) << "the claimed 900 MB were allocated";
}

TEST_F(RecordingTest, ACorruptByteStopsAtThatRecord)
{
	{
		std::fstream f(path_, std::ios::in | std::ios::out | std::ios::binary);
		f.seekp(static_cast<std::streamoff>(sizes_[1] + 200));
		f.put('\x5a');
	}
	RecordingReader reader(path_);
	EXPECT_EQ(read_all(reader), 2U);
	EXPECT_NE(reader.report().reason.find("CRC"), std::string::npos) << reader.report().reason;
}

TEST(Recording, RejectsWhatIsNotARecording)
{
	const auto path = (fs::temp_directory_path() / "stereod-not-a-recording.srec").string();
	std::ofstream(path) << "hello";
	EXPECT_THROW({ RecordingReader reader(path); }, std::runtime_error);
	fs::remove(path);
	EXPECT_THROW({ RecordingReader reader("/nonexistent/x.srec"); }, std::runtime_error);
}

// Found by reading what the fuzz target could not reach (the header's CRC guards it from random bytes): a
// header with a valid CRC but a geometry no camera has (negative, zero or gigantic sizes) made the reader's
// caller allocate it: cv::Exception (not a runtime_error) or gigabytes. Refused at open, naming the path.
// Found by fuzz_recording (out of memory): a constructor that throws runs no destructor, so every refused
// recording leaked its open FILE. Refusing many files must not grow the process's open descriptors.
TEST(Recording, ARefusedFileIsClosed)
{
	const auto path =
		(fs::temp_directory_path() / ("stereod-refused-" + std::to_string(::getpid()) + ".srec")).string();
	std::ofstream(path) << "not a recording, but long enough to be read as one's magic";
	const auto open_fds = [] {
		return std::distance(fs::directory_iterator("/proc/self/fd"), fs::directory_iterator{});
	};
	const auto before = open_fds();
	for (int i = 0; i < 200; ++i)
		EXPECT_THROW({ RecordingReader reader(path); }, std::runtime_error);
	EXPECT_EQ(open_fds(), before);
	fs::remove(path);
}

TEST(Recording, RefusesAnImplausibleGeometry)
{
	const auto path =
		(fs::temp_directory_path() / ("stereod-geometry-" + std::to_string(::getpid()) + ".srec")).string();
	for (const auto &[w, h] :
	     {std::pair{-4, 10}, std::pair{0, 10}, std::pair{100000, 100000}, std::pair{640, -1}}) {
		FrameGeometry g;
		g.width = w;
		g.height = h;
		{
			RecordingWriter writer(path, {"sim", "forged", g, 0});
		}
		try {
			RecordingReader reader(path);
			ADD_FAILURE() << w << "x" << h << " was accepted";
		} catch (const std::runtime_error &e) {
			EXPECT_NE(std::string(e.what()).find("implausible image size"), std::string::npos) << e.what();
			EXPECT_NE(std::string(e.what()).find(path), std::string::npos);
		}
	}
	fs::remove(path);
}

// The daemon's live recorder (daemon/live_recorder.hpp): two workers offering at once, more frames than it
// has slots. Every frame is either in the file, whole (its pixels are its sequence number), or counted as
// dropped; none is torn or written twice. Runs under TSan too.
TEST(LiveRecorder, ConcurrentOffersAreRecordedWholeOrCounted)
{
	const auto path =
		(fs::temp_directory_path() / ("stereod-live-" + std::to_string(::getpid()) + ".srec")).string();
	fs::remove(path);
	FrameGeometry g;
	g.width = 32;
	g.height = 8;
	g.format = PixelFormat::Mono8;
	constexpr int kPerThread = 300;
	uint64_t frames = 0, dropped = 0;
	{
		stereod::daemon::LiveRecorder recorder(path, {"sim", "live test", g, 0}, 4, false);
		auto worker = [&](int parity) {
			StereoFrame f;
			f.allocate(g);
			for (int i = 0; i < kPerThread; ++i) {
				const int seq = 2 * i + parity;
				f.sequence = static_cast<uint64_t>(seq);
				f.left.setTo(cv::Scalar(seq % 251));
				recorder.offer(f);
				if (i % 16 == 0)
					std::this_thread::sleep_for(std::chrono::microseconds(200));
			}
		};
		std::thread a(worker, 0), b(worker, 1);
		a.join();
		b.join();
		// Let the writer finish what is queued before looking (the destructor would too).
		for (int i = 0; i < 200 && recorder.stats().frames + recorder.stats().dropped < 2 * kPerThread; ++i)
			std::this_thread::sleep_for(std::chrono::milliseconds(5));
		const auto s = recorder.stats();
		frames = s.frames;
		dropped = s.dropped;
		EXPECT_EQ(s.state, "recording");
	}
	EXPECT_EQ(frames + dropped, 2U * kPerThread);
	EXPECT_GT(frames, 0U);
	RecordingReader reader(path);
	StereoFrame f;
	f.allocate(reader.header().geometry);
	std::set<uint64_t> seen;
	while (reader.next(f)) {
		EXPECT_TRUE(seen.insert(f.sequence).second) << "frame " << f.sequence << " written twice";
		double lo = 0, hi = 0;
		cv::minMaxLoc(f.left, &lo, &hi);
		EXPECT_EQ(lo, static_cast<double>(f.sequence % 251)) << "frame " << f.sequence << " torn";
		EXPECT_EQ(hi, lo);
	}
	EXPECT_TRUE(reader.report().clean_end);
	EXPECT_EQ(seen.size(), frames);
	fs::remove(path);
}
