#pragma once
// The project's recording format (.srec), documented in docs/recording-format.md.
//
// Append-only: a header, then one self-contained record per frame, each written with a single write() and
// protected by its length and a CRC-32. A recorder killed at any instant leaves a file whose every complete
// record is readable; the reader stops at the first record that is cut short or fails its CRC and says so.
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "core/frame.hpp"

namespace stereod::drivers {

struct RecordingHeader {
	std::string source; ///< driver that produced the frames
	std::string description;
	FrameGeometry geometry;
	int64_t created_unix_ns = 0;

	/// A header stamped with the wall-clock time now.
	static RecordingHeader stamped_now(std::string source, std::string description, const FrameGeometry &geometry);
};

/// The header as the JSON both formats carry (.srec's file header, MCAP's raw channel metadata).
std::string recording_header_json(const RecordingHeader &header);
/// Parses and checks it (image size 1..16384 a side). Throws std::runtime_error saying what is wrong.
RecordingHeader parse_recording_header(const std::string &json);
/// One frame as the .srec record payload (docs/recording-format.md), appended to `out`; MCAP's raw channel
/// carries the same bytes.
void encode_frame(const StereoFrame &frame, const FrameGeometry &geometry, std::vector<uint8_t> &out);
/// The reverse, into a frame allocated at `geometry`. Throws std::runtime_error on a malformed payload.
void decode_frame(const uint8_t *data, size_t size, const FrameGeometry &geometry, StereoFrame &into);

/// Anything frames are recorded to: a .srec (RecordingWriter) or an MCAP file (drivers/replay/mcap_recording).
class FrameRecorder
{
public:
	virtual ~FrameRecorder() = default;
	/// Appends one frame. `sync` forces what is written to the disk before returning. Throws
	/// std::runtime_error on a failed write; everything written before stays readable.
	virtual void append(const StereoFrame &frame, bool sync = false) = 0;
	/// The processed result of a frame (a protocol `frame` message), where the format carries results.
	virtual void append_result(int64_t t_capture_ns, const std::string &message)
	{
		(void)t_capture_ns;
		(void)message;
	}
	[[nodiscard]] virtual bool records_results() const { return false; }
	/// Writes what is buffered and closes the file's structure (MCAP's summary). Throws on a failed write.
	virtual void finish() {}
	[[nodiscard]] virtual uint64_t frames_written() const = 0;
	[[nodiscard]] virtual uint64_t bytes_written() const = 0;
};

/// Anything frames are replayed from.
class FrameRecordingReader
{
public:
	virtual ~FrameRecordingReader() = default;
	[[nodiscard]] virtual const RecordingHeader &recording_header() const = 0;
	/// Reads the next frame into `into` (allocated at the header's geometry). False at the end of the valid
	/// data; describe_end() then says whether the end was clean or what was cut.
	virtual bool next_frame(StereoFrame &into) = 0;
	[[nodiscard]] virtual std::string describe_end() const = 0;
};

struct RecorderOptions {
	bool raw = true;      ///< MCAP: lossless frames (what replay reads)
	bool images = false;  ///< MCAP: JPEG images as foxglove.CompressedImage (what Foxglove shows)
	bool results = false; ///< MCAP: a channel for processed results
	int jpeg_quality = 90;
	int64_t chunk_ns = 1'000'000'000; ///< MCAP: the longest a chunk stays open (what a SIGKILL can cost)
};

/// True for a path whose format is MCAP (by its extension, `.mcap`).
bool is_mcap_path(const std::string &path);
/// A recorder for `path`: MCAP for `.mcap`, else .srec. Throws std::runtime_error naming the path.
std::unique_ptr<FrameRecorder> open_recorder(const std::string &path, const RecordingHeader &header,
					     const RecorderOptions &options = {});
/// A reader for `path`, by its content (MCAP's magic, else .srec). Throws std::runtime_error naming the path.
std::unique_ptr<FrameRecordingReader> open_recording(const std::string &path);

class RecordingWriter final : public FrameRecorder
{
public:
	/// Creates (truncates) `path` and writes the header. Throws std::runtime_error naming the path.
	RecordingWriter(const std::string &path, const RecordingHeader &header);
	~RecordingWriter();
	RecordingWriter(const RecordingWriter &) = delete;
	RecordingWriter &operator=(const RecordingWriter &) = delete;

	/// Appends one frame as one record. `sync` forces it to the disk before returning.
	void append(const StereoFrame &frame, bool sync = false) override;
	[[nodiscard]] uint64_t frames_written() const override { return frames_; }
	[[nodiscard]] uint64_t bytes_written() const override { return bytes_; }

private:
	void write_all(const uint8_t *data, size_t size);

	std::string path_;
	int fd_ = -1;
	FrameGeometry geometry_;
	std::vector<uint8_t> buffer_; ///< reused record buffer
	uint64_t frames_ = 0;
	uint64_t bytes_ = 0;
};

/// What a reader found when it reached the end of a recording.
struct RecoveryReport {
	uint64_t frames = 0;	    ///< complete, valid records read
	bool clean_end = true;	    ///< the file ended exactly after a complete record
	uint64_t cut_at_offset = 0; ///< where the first unreadable record starts
	uint64_t bytes_dropped = 0; ///< bytes from there to the end of the file
	std::string reason;	    ///< why that record was unreadable
	[[nodiscard]] std::string describe() const;
};

class RecordingReader final : public FrameRecordingReader
{
public:
	/// Opens and validates the header. Throws std::runtime_error naming the path and the problem.
	explicit RecordingReader(const std::string &path);
	~RecordingReader();
	RecordingReader(const RecordingReader &) = delete;
	RecordingReader &operator=(const RecordingReader &) = delete;

	[[nodiscard]] const RecordingHeader &header() const { return header_; }
	/// Reads the next frame into `into` (allocated at header().geometry). False at the end of the valid
	/// data; report() then says whether the end was clean or what was cut.
	bool next(StereoFrame &into);
	[[nodiscard]] const RecoveryReport &report() const { return report_; }

	[[nodiscard]] const RecordingHeader &recording_header() const override { return header_; }
	bool next_frame(StereoFrame &into) override { return next(into); }
	[[nodiscard]] std::string describe_end() const override { return report_.describe(); }

private:
	void read_header();
	bool fail(const std::string &reason);

	std::string path_;
	std::FILE *file_ = nullptr;
	uint64_t file_size_ = 0;
	uint64_t offset_ = 0;
	RecordingHeader header_;
	std::vector<uint8_t> buffer_;
	RecoveryReport report_;
	bool done_ = false;
};

} // namespace stereod::drivers
