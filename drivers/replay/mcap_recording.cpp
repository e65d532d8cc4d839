#include "drivers/replay/mcap_recording.hpp"

#include <optional>

#include <array>
#include <cstring>
#include <stdexcept>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/protocol.hpp"

namespace stereod::drivers {
namespace {

// Foxglove's CompressedImage as a JSON Schema (its published schema, JSON flavour: bytes as base64).
constexpr const char *kCompressedImageSchema = R"schema({
  "title": "foxglove.CompressedImage",
  "description": "A compressed image",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "title": "time", "properties": {
      "sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
    "frame_id": {"type": "string", "description": "Frame of reference for the image"},
    "data": {"type": "string", "contentEncoding": "base64", "description": "Compressed image data"},
    "format": {"type": "string", "description": "Image format: jpeg, png, webp or avif"}
  }
})schema";

constexpr char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

std::string base64_encode(const std::vector<uint8_t> &in)
{
	std::string out;
	out.reserve((in.size() + 2) / 3 * 4);
	size_t i = 0;
	for (; i + 2 < in.size(); i += 3) {
		const uint32_t v = (uint32_t{in[i]} << 16) | (uint32_t{in[i + 1]} << 8) | in[i + 2];
		out += kBase64[(v >> 18) & 63];
		out += kBase64[(v >> 12) & 63];
		out += kBase64[(v >> 6) & 63];
		out += kBase64[v & 63];
	}
	if (i + 1 == in.size()) {
		const uint32_t v = uint32_t{in[i]} << 16;
		out += kBase64[(v >> 18) & 63];
		out += kBase64[(v >> 12) & 63];
		out += "==";
	} else if (i + 2 == in.size()) {
		const uint32_t v = (uint32_t{in[i]} << 16) | (uint32_t{in[i + 1]} << 8);
		out += kBase64[(v >> 18) & 63];
		out += kBase64[(v >> 12) & 63];
		out += kBase64[(v >> 6) & 63];
		out += '=';
	}
	return out;
}

std::vector<uint8_t> base64_decode(const std::string &in)
{
	std::array<int, 256> value{};
	value.fill(-1);
	for (int i = 0; i < 64; ++i)
		value[static_cast<uint8_t>(kBase64[i])] = i;
	std::vector<uint8_t> out;
	out.reserve(in.size() / 4 * 3);
	uint32_t acc = 0;
	int bits = 0;
	for (const char c : in) {
		if (c == '=')
			break;
		const int v = value[static_cast<uint8_t>(c)];
		if (v < 0)
			throw std::runtime_error("image data is not base64");
		acc = (acc << 6) | static_cast<uint32_t>(v);
		bits += 6;
		if (bits >= 8) {
			bits -= 8;
			out.push_back(static_cast<uint8_t>((acc >> bits) & 0xff));
		}
	}
	return out;
}

uint64_t log_time(int64_t t_ns)
{
	return t_ns > 0 ? static_cast<uint64_t>(t_ns) : 0;
}

/// Replays frames from an MCAP file: the lossless raw channel, or else the JPEG image channels.
class McapRecordingReader final : public FrameRecordingReader
{
public:
	explicit McapRecordingReader(const std::string &path) : path_(path), reader_(path)
	{
		reader_.read_definitions();
		std::string topics;
		for (const auto &[id, channel] : reader_.channels()) {
			topics += (topics.empty() ? "" : ", ") + channel.topic;
			const auto header = channel.metadata.find("recording_header");
			if (header == channel.metadata.end())
				continue;
			if (channel.topic == kMcapRawTopic && channel.message_encoding == kMcapRawEncoding) {
				raw_ = static_cast<int>(id);
				header_json_ = header->second;
			} else if (channel.topic == kMcapLeftImageTopic) {
				left_ = static_cast<int>(id);
				if (header_json_.empty())
					header_json_ = header->second;
			} else if (channel.topic == kMcapRightImageTopic) {
				right_ = static_cast<int>(id);
			}
		}
		if (raw_ < 0 && left_ < 0)
			throw std::runtime_error(path + ": no frames to replay: neither " + kMcapRawTopic + " nor " +
						 kMcapLeftImageTopic + " with a recording header (channels: " +
						 (topics.empty() ? "none" : topics) + ")");
		try {
			header_ = parse_recording_header(header_json_);
		} catch (const std::exception &e) {
			throw std::runtime_error(path + ": bad recording header: " + e.what());
		}
		if (raw_ < 0) {
			// From JPEG images only the eyes come back; depth and truth are not in them.
			header_.geometry.depth = false;
			header_.geometry.truth = false;
			header_.geometry.stereo = header_.geometry.stereo && right_ >= 0;
		}
	}

	const RecordingHeader &recording_header() const override { return header_; }

	bool next_frame(StereoFrame &into) override
	{
		if (!error_.empty())
			return false;
		mcap::MessageView m;
		while (reader_.next(m)) {
			const int channel = m.channel->id;
			try {
				if (channel == raw_) {
					decode_frame(m.data.data(), m.data.size(), header_.geometry, into);
					++frames_;
					return true;
				}
				if (raw_ >= 0)
					continue;
				if (channel == left_) {
					decode_image(m, into.left);
					into.sequence = frames_;
					into.device_ns = static_cast<int64_t>(m.log_time);
					into.host_ns = into.device_ns;
					into.lr_skew_ns = 0;
					into.status = FrameStatus::Ok;
					into.truth.object_count = 0;
					have_left_ = m.log_time;
					if (!header_.geometry.stereo) {
						++frames_;
						return true;
					}
				} else if (channel == right_ && have_left_ && *have_left_ == m.log_time) {
					decode_image(m, into.right);
					have_left_.reset();
					++frames_;
					return true;
				}
			} catch (const std::exception &e) {
				error_ = "message " + std::to_string(reader_.report().messages) + " on " +
					 m.channel->topic + " is malformed: " + e.what();
				return false;
			}
		}
		return false;
	}

	std::string describe_end() const override
	{
		std::string s = std::to_string(frames_) + " frames from " + (raw_ >= 0 ? "raw" : "JPEG") +
				" channels; " + reader_.report().describe();
		if (!error_.empty())
			s += "; stopped: " + error_;
		return s;
	}

private:
	void decode_image(const mcap::MessageView &m, cv::Mat &target)
	{
		const auto j = nlohmann::json::parse(m.data.begin(), m.data.end());
		const auto bytes = base64_decode(j.at("data").get<std::string>());
		const cv::Mat image = cv::imdecode(
			bytes, header_.geometry.format == PixelFormat::Mono8 ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
		if (image.empty() || image.size() != target.size() || image.type() != target.type())
			throw std::runtime_error("image does not decode to the recording's geometry");
		image.copyTo(target);
	}

	std::string path_;
	mcap::Reader reader_;
	std::string header_json_;
	RecordingHeader header_;
	int raw_ = -1, left_ = -1, right_ = -1;
	std::optional<uint64_t> have_left_;
	uint64_t frames_ = 0;
	std::string error_;
};

} // namespace

McapRecorder::McapRecorder(const std::string &path, const RecordingHeader &header, const RecorderOptions &options)
	: writer_(path,
		  mcap::WriterOptions{
			  .profile = "", .library = "stereod", .chunk_ns = options.chunk_ns, .sync = false}),
	  options_(options), geometry_(header.geometry)
{
	const std::string header_json = recording_header_json(header);
	if (options.raw)
		raw_channel_ =
			writer_.add_channel(0, kMcapRawTopic, kMcapRawEncoding, {{"recording_header", header_json}});
	if (options.images) {
		const uint16_t schema =
			writer_.add_schema("foxglove.CompressedImage", "jsonschema", kCompressedImageSchema);
		left_channel_ =
			writer_.add_channel(schema, kMcapLeftImageTopic, "json", {{"recording_header", header_json}});
		if (header.geometry.stereo)
			right_channel_ = writer_.add_channel(schema, kMcapRightImageTopic, "json", {});
	}
	if (options.results) {
		const uint16_t schema =
			writer_.add_schema("stereod.Frame", "jsonschema", std::string(protocol::frame_json_schema()));
		results_channel_ = writer_.add_channel(schema, kMcapResultsTopic, "json", {});
	}
}

std::string McapRecorder::image_message(const cv::Mat &image, int64_t t_capture_ns, const std::string &frame_id,
					int jpeg_quality)
{
	std::vector<uint8_t> jpeg;
	if (!cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, jpeg_quality}))
		throw std::runtime_error("JPEG encoding failed");
	const uint64_t t = log_time(t_capture_ns);
	const nlohmann::json message = {{"timestamp", {{"sec", t / 1'000'000'000}, {"nsec", t % 1'000'000'000}}},
					{"frame_id", frame_id},
					{"data", base64_encode(jpeg)},
					{"format", "jpeg"}};
	return message.dump();
}

void McapRecorder::append_image_message(int64_t t_capture_ns, bool right, const std::string &message, bool hold)
{
	const int channel = right ? right_channel_ : left_channel_;
	if (channel < 0)
		return;
	writer_.write(static_cast<uint16_t>(channel), log_time(t_capture_ns), log_time(t_capture_ns),
		      {reinterpret_cast<const uint8_t *>(message.data()), message.size()}, hold);
}

void McapRecorder::append(const StereoFrame &frame, bool sync)
{
	const uint64_t t = log_time(frame.device_ns);
	if (raw_channel_ >= 0) {
		buffer_.clear();
		encode_frame(frame, geometry_, buffer_);
		writer_.write(static_cast<uint16_t>(raw_channel_), t, t, buffer_, true);
	}
	if (left_channel_ >= 0)
		append_image_message(frame.device_ns, false,
				     image_message(frame.left, frame.device_ns, "left", options_.jpeg_quality), true);
	if (right_channel_ >= 0)
		append_image_message(frame.device_ns, true,
				     image_message(frame.right, frame.device_ns, "right", options_.jpeg_quality), true);
	++frames_;
	// The frame's messages share a chunk: a crash keeps or loses the frame whole.
	if (sync)
		writer_.flush(true);
	else
		writer_.maybe_flush();
}

void McapRecorder::append_result(int64_t t_capture_ns, const std::string &message)
{
	if (results_channel_ < 0)
		return;
	writer_.write(static_cast<uint16_t>(results_channel_), log_time(t_capture_ns), log_time(t_capture_ns),
		      {reinterpret_cast<const uint8_t *>(message.data()), message.size()});
}

bool is_mcap_path(const std::string &path)
{
	return path.size() >= 5 && path.compare(path.size() - 5, 5, ".mcap") == 0;
}

std::unique_ptr<FrameRecorder> open_recorder(const std::string &path, const RecordingHeader &header,
					     const RecorderOptions &options)
{
	if (is_mcap_path(path))
		return std::make_unique<McapRecorder>(path, header, options);
	return std::make_unique<RecordingWriter>(path, header);
}

std::unique_ptr<FrameRecordingReader> open_recording(const std::string &path)
{
	if (mcap::is_mcap_file(path))
		return std::make_unique<McapRecordingReader>(path);
	return std::make_unique<RecordingReader>(path);
}

} // namespace stereod::drivers
