// MCAP writer and reader (drivers/replay/mcap.hpp) and stereod's frames in it (mcap_recording.hpp). The
// independent check, Foxglove's own reader, is tests/mcap/check_mcap.mjs (integration.mcap, data.vtest_mcap).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include <nlohmann/json.hpp>

#include "core/protocol.hpp"
#include "drivers/replay/mcap.hpp"
#include "drivers/replay/mcap_recording.hpp"

using namespace stereod;
using namespace stereod::drivers;
namespace fs = std::filesystem;

namespace {

std::string temp_path(const std::string &name)
{
	return (fs::temp_directory_path() / ("stereod-mcap-" + std::to_string(::getpid()) + "-" + name)).string();
}

std::vector<uint8_t> payload(size_t i)
{
	std::vector<uint8_t> p(1 + (i * 37) % 300);
	for (size_t k = 0; k < p.size(); ++k)
		p[k] = static_cast<uint8_t>(i * 7 + k);
	return p;
}

struct Written {
	uint16_t channel;
	uint64_t time;
	std::vector<uint8_t> data;
	uint64_t file_size_after_chunk; ///< where the chunk record holding this message ends in the file
};

/// Marks messages [from, to) as in the chunk just written: it ends before its message indexes (one per
/// channel: opcode, length, channel id, array length, 16 bytes an entry), which the file ends with now.
void mark_chunk(std::vector<Written> &written, size_t from, size_t to, uint64_t file_size)
{
	std::map<uint16_t, uint64_t> per_channel;
	for (size_t k = from; k < to; ++k)
		++per_channel[written[k].channel];
	uint64_t index_bytes = 0;
	for (const auto &[channel, n] : per_channel)
		index_bytes += 9 + 2 + 4 + 16 * n;
	for (size_t k = from; k < to; ++k)
		written[k].file_size_after_chunk = file_size - index_bytes;
}

/// 40 messages on two channels in chunks of ~1 KB; returns them in file order.
std::vector<Written> write_sample(const std::string &path, bool finish = true)
{
	mcap::WriterOptions options;
	options.chunk_bytes = 1024;
	options.chunk_ns = int64_t{1} << 62;
	mcap::Writer writer(path, options);
	const uint16_t schema = writer.add_schema("test.Thing", "jsonschema", R"({"type":"object"})");
	const uint16_t a = writer.add_channel(schema, "/a", "json", {{"k", "v"}});
	const uint16_t b = writer.add_channel(0, "/b", "private", {});
	writer.add_metadata("about", {{"what", "a test"}});
	std::vector<Written> written;
	size_t pending_from = 0;
	for (size_t i = 0; i < 40; ++i) {
		const uint16_t channel = i % 3 == 0 ? b : a;
		written.push_back({channel, 1000 + i * 10, payload(i), 0});
		const uint64_t chunks_before = writer.chunks_written();
		writer.write(channel, written.back().time, written.back().time, written.back().data);
		if (writer.chunks_written() != chunks_before) {
			mark_chunk(written, pending_from, i + 1, writer.bytes_written());
			pending_from = i + 1;
		}
	}
	if (finish) {
		writer.flush();
		mark_chunk(written, pending_from, written.size(), writer.bytes_written());
		writer.finish();
	}
	return written;
}

} // namespace

TEST(Mcap, WritesAndReadsBackEveryMessageInOrder)
{
	const std::string path = temp_path("roundtrip.mcap");
	const auto written = write_sample(path);
	mcap::Reader reader(path);
	EXPECT_EQ(reader.library(), "stereod");
	mcap::MessageView m;
	size_t i = 0;
	std::map<uint16_t, uint32_t> sequences;
	while (reader.next(m)) {
		ASSERT_LT(i, written.size());
		EXPECT_EQ(m.channel->id, written[i].channel);
		EXPECT_EQ(m.log_time, written[i].time);
		EXPECT_EQ(m.publish_time, written[i].time);
		EXPECT_EQ(m.sequence, sequences[m.channel->id]++) << "sequence numbers count per channel";
		EXPECT_EQ(std::vector<uint8_t>(m.data.begin(), m.data.end()), written[i].data);
		++i;
	}
	EXPECT_EQ(i, written.size());
	EXPECT_TRUE(reader.report().clean_end) << reader.report().describe();
	EXPECT_TRUE(reader.report().data_crc_checked);
	EXPECT_GT(reader.report().chunks, 5U);
	ASSERT_EQ(reader.channels().size(), 2U);
	EXPECT_EQ(reader.channels().at(0).metadata.at("k"), "v");
	EXPECT_EQ(reader.schemas().at(1).name, "test.Thing");
	ASSERT_EQ(reader.metadata().size(), 1U);
	EXPECT_EQ(reader.metadata()[0].second.at("what"), "a test");

	const auto index = reader.check_index();
	EXPECT_TRUE(index.present);
	EXPECT_TRUE(index.valid) << (index.problems.empty() ? "" : index.problems[0]);
	EXPECT_EQ(index.indexed_messages, written.size());
	EXPECT_EQ(index.statistics_messages, written.size());
	EXPECT_EQ(index.chunk_indexes, reader.report().chunks);
	fs::remove(path);
}

TEST(Mcap, AFileCutAnywhereKeepsEveryCompleteChunkAndNothingElse)
{
	// What a SIGKILL leaves: the file cut at any byte. Every cut is read without a crash, delivers exactly the
	// messages of the chunks wholly before it, and says where it was cut.
	const std::string path = temp_path("whole.mcap");
	const auto written = write_sample(path);
	std::ifstream in(path, std::ios::binary);
	const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
	const std::string cut_path = temp_path("cut.mcap");
	size_t checked = 0;
	for (size_t size = 40; size < bytes.size(); size += 7) {
		{
			std::ofstream out(cut_path, std::ios::binary | std::ios::trunc);
			out.write(bytes.data(), static_cast<std::streamsize>(size));
		}
		size_t expected = 0;
		for (const auto &w : written)
			expected += w.file_size_after_chunk <= size;
		mcap::Reader reader(cut_path);
		mcap::MessageView m;
		size_t got = 0;
		while (reader.next(m)) {
			ASSERT_LT(got, written.size());
			ASSERT_EQ(std::vector<uint8_t>(m.data.begin(), m.data.end()), written[got].data);
			++got;
		}
		ASSERT_EQ(got, expected) << "cut at " << size << ": " << reader.report().describe();
		EXPECT_FALSE(reader.report().clean_end);
		EXPECT_FALSE(reader.report().reason.empty());
		EXPECT_FALSE(reader.check_index().present) << "a cut file has no footer";
		++checked;
	}
	EXPECT_GT(checked, 100U);
	fs::remove(path);
	fs::remove(cut_path);
}

TEST(Mcap, ACorruptChunkStopsTheReadAtThatChunk)
{
	const std::string path = temp_path("corrupt.mcap");
	const auto written = write_sample(path);
	// Flip a byte inside the third chunk's records: half way between the second and third chunk's ends (a
	// chunk is ~1 KB; its header and the message indexes before it are far smaller).
	std::vector<uint64_t> ends;
	for (const auto &w : written)
		if (ends.empty() || ends.back() != w.file_size_after_chunk)
			ends.push_back(w.file_size_after_chunk);
	ASSERT_GE(ends.size(), 3U);
	size_t kept = 0;
	for (const auto &w : written)
		kept += w.file_size_after_chunk <= ends[1];
	std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
	const auto at = static_cast<std::streamoff>((ends[1] + ends[2]) / 2);
	f.seekg(at);
	char c = 0;
	f.get(c);
	f.seekp(at);
	f.put(static_cast<char>(c ^ 0x20));
	f.close();
	mcap::Reader reader(path);
	mcap::MessageView m;
	size_t got = 0;
	while (reader.next(m))
		++got;
	EXPECT_EQ(got, kept);
	EXPECT_EQ(reader.report().reason, "chunk fails its CRC") << reader.report().describe();
	fs::remove(path);
}

TEST(Mcap, ACorruptSummaryIsFound)
{
	const std::string path = temp_path("summary.mcap");
	write_sample(path);
	const auto size = fs::file_size(path);
	std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
	f.seekg(static_cast<std::streamoff>(size - 8 - 29 - 40)); // inside the summary offsets / statistics
	char c = 0;
	f.get(c);
	f.seekp(static_cast<std::streamoff>(size - 8 - 29 - 40));
	f.put(static_cast<char>(c ^ 0x01));
	f.close();
	mcap::Reader reader(path);
	const auto index = reader.check_index();
	EXPECT_TRUE(index.present);
	EXPECT_FALSE(index.valid);
	ASSERT_FALSE(index.problems.empty());
	EXPECT_EQ(index.problems[0], "summary fails its CRC");
	fs::remove(path);
}

TEST(Mcap, RefusesWhatIsNotMcap)
{
	const std::string path = temp_path("not.mcap");
	std::ofstream(path) << "SREC this is not an MCAP file at all";
	EXPECT_THROW(mcap::Reader{path}, std::runtime_error);
	fs::remove(path);
	EXPECT_THROW(mcap::Reader{path}, std::runtime_error);
}

namespace {

FrameGeometry small_geometry()
{
	return {48, 32, PixelFormat::Bgr8, true, false, true, 30};
}

void fill(StereoFrame &f, uint64_t i)
{
	cv::RNG rng(i + 1);
	f.sequence = i;
	f.device_ns = 1'000'000'000 + static_cast<int64_t>(i) * 33'333'333;
	f.host_ns = 5 + static_cast<int64_t>(i);
	f.lr_skew_ns = static_cast<int64_t>(i % 4);
	f.status = i == 3 ? FrameStatus::Incomplete : FrameStatus::Ok;
	rng.fill(f.left, cv::RNG::UNIFORM, 0, 256);
	rng.fill(f.right, cv::RNG::UNIFORM, 0, 256);
	f.truth.object_ids.setTo(static_cast<double>(i % 7));
	f.truth.object_count = 1;
	f.truth.objects[0] = {4, {1.0, 2.0, static_cast<double>(i)}, {0.25, 0, 0}};
}

bool same_pixels(const cv::Mat &a, const cv::Mat &b)
{
	return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

} // namespace

TEST(McapRecording, RawFramesReplayLosslesslyAndResultsAndImagesAreThere)
{
	const std::string path = temp_path("frames.mcap");
	RecorderOptions options;
	options.images = true;
	options.results = true;
	{
		auto recorder = open_recorder(path, RecordingHeader::stamped_now("sim", "unit test", small_geometry()),
					      options);
		ASSERT_TRUE(recorder->records_results());
		StereoFrame frame;
		frame.allocate(small_geometry());
		for (uint64_t i = 0; i < 12; ++i) {
			fill(frame, i);
			recorder->append(frame);
			recorder->append_result(frame.device_ns,
						R"({"v":1,"type":"frame","seq":)" + std::to_string(i) + "}");
		}
		recorder->finish();
		EXPECT_EQ(recorder->frames_written(), 12U);
	}
	auto reader = open_recording(path);
	EXPECT_EQ(reader->recording_header().source, "sim");
	EXPECT_EQ(reader->recording_header().geometry.width, 48);
	EXPECT_TRUE(reader->recording_header().geometry.truth);
	StereoFrame got, want;
	got.allocate(small_geometry());
	want.allocate(small_geometry());
	uint64_t n = 0;
	while (reader->next_frame(got)) {
		fill(want, n);
		EXPECT_EQ(got.sequence, want.sequence);
		EXPECT_EQ(got.device_ns, want.device_ns);
		EXPECT_EQ(got.lr_skew_ns, want.lr_skew_ns);
		EXPECT_EQ(got.status, want.status);
		EXPECT_TRUE(same_pixels(got.left, want.left));
		EXPECT_TRUE(same_pixels(got.right, want.right));
		EXPECT_TRUE(same_pixels(got.truth.object_ids, want.truth.object_ids));
		EXPECT_EQ(got.truth.objects[0].position_m[2], static_cast<double>(n));
		++n;
	}
	EXPECT_EQ(n, 12U) << reader->describe_end();

	mcap::Reader raw(path);
	std::map<std::string, int> topics;
	mcap::MessageView m;
	while (raw.next(m)) {
		++topics[m.channel->topic];
		if (m.channel->topic == kMcapLeftImageTopic) {
			const auto j = nlohmann::json::parse(m.data.begin(), m.data.end());
			EXPECT_EQ(j.at("format"), "jpeg");
			EXPECT_EQ(j.at("frame_id"), "left");
			EXPECT_EQ(j.at("timestamp").at("sec").get<uint64_t>() * 1'000'000'000 +
					  j.at("timestamp").at("nsec").get<uint64_t>(),
				  m.log_time);
		}
	}
	EXPECT_EQ(topics[kMcapRawTopic], 12);
	EXPECT_EQ(topics[kMcapLeftImageTopic], 12);
	EXPECT_EQ(topics[kMcapRightImageTopic], 12);
	EXPECT_EQ(topics[kMcapResultsTopic], 12);
	for (const auto &[id, schema] : raw.schemas())
		EXPECT_TRUE(nlohmann::json::accept(schema.data)) << schema.name;
	fs::remove(path);
}

TEST(McapRecording, ImagesAloneReplayThroughJpeg)
{
	const std::string path = temp_path("images.mcap");
	RecorderOptions options;
	options.raw = false;
	options.images = true;
	FrameGeometry g = small_geometry();
	{
		McapRecorder recorder(path, RecordingHeader::stamped_now("sim", "jpeg only", g), options);
		StereoFrame frame;
		frame.allocate(g);
		for (uint64_t i = 0; i < 4; ++i) {
			fill(frame, i);
			frame.left.setTo(cv::Scalar(40.0 * static_cast<double>(i), 100, 200)); // smooth: JPEG keeps it
			recorder.append(frame);
		}
	}
	auto reader = open_recording(path);
	EXPECT_FALSE(reader->recording_header().geometry.truth) << "JPEG carries no truth";
	StereoFrame got;
	got.allocate(reader->recording_header().geometry);
	uint64_t n = 0;
	while (reader->next_frame(got)) {
		const cv::Scalar mean = cv::mean(got.left);
		EXPECT_NEAR(mean[0], 40.0 * static_cast<double>(n), 3.0);
		EXPECT_NEAR(mean[2], 200.0, 3.0);
		++n;
	}
	EXPECT_EQ(n, 4U) << reader->describe_end();
	fs::remove(path);
}

TEST(McapRecording, ResultsOnlyFileIsRefusedAsASourceWithAReason)
{
	const std::string path = temp_path("results.mcap");
	RecorderOptions options;
	options.raw = false;
	options.results = true;
	{
		McapRecorder recorder(path, RecordingHeader::stamped_now("sim", "results", small_geometry()), options);
		recorder.append_result(1, R"({"v":1})");
	}
	try {
		(void)open_recording(path);
		FAIL() << "a file of results alone was taken as frames";
	} catch (const std::runtime_error &e) {
		EXPECT_NE(std::string(e.what()).find("no frames to replay"), std::string::npos) << e.what();
	}
	fs::remove(path);
}

TEST(McapRecording, FrameSchemaDescribesEveryFieldOfAFullMessage)
{
	const auto schema = nlohmann::json::parse(protocol::frame_json_schema());
	FrameResult r;
	r.seq = 3;
	r.points.push_back({});
	r.points.back().xyz_m = std::array<float, 3>{1, 2, 3};
	r.points.back().track = 4;
	r.points.back().in_person = true;
	r.ego = EgoMotion{};
	r.ego->homography = std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, 1};
	r.ego->valid = true;
	r.ego->t_prev_curr = std::array<double, 16>{};
	r.ego->t_world_curr = std::array<double, 16>{};
	r.ego->keyframe = true;
	r.ego->covisibility = 0.5;
	r.stereo = StereoSummary{};
	r.groups.push_back({});
	r.groups.back().position_m = std::array<double, 3>{};
	r.groups.back().extent_m = std::array<double, 3>{};
	r.groups.back().velocity_mps = std::array<double, 3>{};
	r.groups.back().world_velocity_mps = std::array<double, 3>{};
	r.groups.back().speed_mps = 1.0;
	r.groups.back().heading_rad = 0.5;
	r.groups.back().class_name = "person";
	r.people.push_back({});
	r.people.back().class_id = 0;
	r.objects.push_back(r.people.back());
	r.timing.push_back({"extract", 1.0});
	const auto message = nlohmann::json::parse(protocol::frame_message(r));
	const auto &props = schema.at("properties");
	// A property is described in place or by a reference to the schema's $defs.
	const auto described = [&](const nlohmann::json &property) -> const nlohmann::json & {
		if (!property.contains("$ref"))
			return property;
		const std::string ref = property.at("$ref");
		EXPECT_EQ(ref.rfind("#/$defs/", 0), 0U) << ref;
		return schema.at("$defs").at(ref.substr(8));
	};
	for (const auto &[key, value] : message.items()) {
		ASSERT_TRUE(props.contains(key)) << "frame field '" << key << "' is not in the schema";
		if (value.is_array() && !value.empty() && value[0].is_object()) {
			const auto &item_props = described(props.at(key)).at("items").at("properties");
			for (const auto &[inner, v] : value[0].items())
				EXPECT_TRUE(item_props.contains(inner))
					<< key << "[]." << inner << " is not in the schema";
		}
		if (value.is_object() && key != "timing_ms") {
			const auto &inner_props = props.at(key).at("properties");
			for (const auto &[inner, v] : value.items())
				EXPECT_TRUE(inner_props.contains(inner))
					<< key << "." << inner << " is not in the schema";
		}
	}
	for (const auto &required : schema.at("required"))
		EXPECT_TRUE(message.contains(required.get<std::string>())) << required;
}
