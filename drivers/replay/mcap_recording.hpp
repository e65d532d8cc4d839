#pragma once
// stereod's frames and results in MCAP (docs/mcap.md): what `stereoctl record --output X.mcap`, live
// recording (`record.path = "X.mcap"`) and `stereod process --output X.mcap` write, and what the `replay`
// driver plays back.
//
// Channels:
//   /stereod/raw               lossless frames: the .srec record payload (docs/recording-format.md), message
//                              encoding `stereod.frame.v1`, no schema; the recording header's JSON is the
//                              channel's `recording_header` metadata. Replay reads these.
//   /stereod/left/compressed   JPEG images as `foxglove.CompressedImage` (jsonschema, JSON with base64 data):
//   /stereod/right/compressed  what Foxglove shows. Replay falls back to them when there is no raw channel.
//   /stereod/frames            processed results: the protocol's `frame` messages (jsonschema `stereod.Frame`)
// Every message's log_time and publish_time are the frame's capture time (t_capture_ns).
#include "drivers/replay/mcap.hpp"
#include "drivers/replay/recording.hpp"

#include <opencv2/core.hpp>

namespace stereod::drivers {

inline constexpr const char *kMcapRawTopic = "/stereod/raw";
inline constexpr const char *kMcapRawEncoding = "stereod.frame.v1";
inline constexpr const char *kMcapLeftImageTopic = "/stereod/left/compressed";
inline constexpr const char *kMcapRightImageTopic = "/stereod/right/compressed";
inline constexpr const char *kMcapResultsTopic = "/stereod/frames";

class McapRecorder final : public FrameRecorder
{
public:
	/// Creates `path` with the channels `options` asks for. Throws std::runtime_error naming the path.
	McapRecorder(const std::string &path, const RecordingHeader &header, const RecorderOptions &options);

	void append(const StereoFrame &frame, bool sync = false) override;
	void append_result(int64_t t_capture_ns, const std::string &message) override;
	[[nodiscard]] bool records_results() const override { return results_channel_ >= 0; }
	void finish() override { writer_.finish(); }
	[[nodiscard]] uint64_t frames_written() const override { return frames_; }
	[[nodiscard]] uint64_t bytes_written() const override { return writer_.bytes_written(); }

	/// The JPEG + base64 image message alone, for callers that encode on their own threads
	/// (`stereod process` encodes on the workers, writes in order).
	static std::string image_message(const cv::Mat &image, int64_t t_capture_ns, const std::string &frame_id,
					 int jpeg_quality);
	/// Writes an image message made by image_message() (`right` for the right eye).
	void append_image_message(int64_t t_capture_ns, bool right, const std::string &message, bool hold = false);

private:
	mcap::Writer writer_;
	RecorderOptions options_;
	FrameGeometry geometry_;
	int raw_channel_ = -1, left_channel_ = -1, right_channel_ = -1, results_channel_ = -1;
	std::vector<uint8_t> buffer_; ///< reused raw payload
	uint64_t frames_ = 0;
};

} // namespace stereod::drivers
