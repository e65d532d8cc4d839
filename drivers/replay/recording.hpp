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
};

class RecordingWriter
{
public:
	/// Creates (truncates) `path` and writes the header. Throws std::runtime_error naming the path.
	RecordingWriter(const std::string &path, const RecordingHeader &header);
	~RecordingWriter();
	RecordingWriter(const RecordingWriter &) = delete;
	RecordingWriter &operator=(const RecordingWriter &) = delete;

	/// Appends one frame as one record. `sync` forces it to the disk before returning.
	void append(const StereoFrame &frame, bool sync = false);
	[[nodiscard]] uint64_t frames_written() const { return frames_; }
	[[nodiscard]] uint64_t bytes_written() const { return bytes_; }

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

class RecordingReader
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
