#pragma once
// MCAP, the container Foxglove and ROS 2 bags use (https://mcap.dev/spec), written and read from the public
// specification: Debian has no MCAP library. This layer knows records, chunks, indexes and CRCs, nothing of
// stereod; drivers/replay/mcap_recording.hpp puts frames and results in it (docs/mcap.md).
//
// The writer is crash-safe in the way .srec is: schemas and channels go to the data section when they are
// added, messages are gathered into a chunk that is written, with its message indexes, by one writev() on an
// O_APPEND descriptor once it passes a size or a span of time. A process killed at any instant leaves every
// complete chunk readable; the summary (schemas, channels, chunk indexes, statistics) and footer come at
// finish(). Chunks are not compressed (`compression` ""): every MCAP reader reads them without a codec, and
// raw camera pixels are what fills them.
#include <cstdint>
#include <cstdio>
#include <map>
#include <span>
#include <string>
#include <vector>

namespace stereod::drivers::mcap {

struct Schema {
	uint16_t id = 0;
	std::string name;
	std::string encoding; ///< "jsonschema", "ros2msg", ... ("" for none)
	std::string data;
};

struct Channel {
	uint16_t id = 0;
	uint16_t schema_id = 0; ///< 0: no schema
	std::string topic;
	std::string message_encoding; ///< "json", "cdr", or a private encoding
	std::map<std::string, std::string> metadata;
};

struct WriterOptions {
	std::string profile;		  ///< the Header's profile ("" or "ros2")
	std::string library = "stereod";  ///< the Header's library field
	size_t chunk_bytes = 4U << 20;	  ///< a chunk is written once its records pass this size...
	int64_t chunk_ns = 1'000'000'000; ///< ...or span this much log time: the most a SIGKILL can cost
	bool sync = false;		  ///< fdatasync after every chunk (a power cut then costs one chunk)
};

class Writer
{
public:
	/// Creates (truncates) `path` and writes the magic and Header. Throws std::runtime_error naming the path.
	Writer(const std::string &path, WriterOptions options);
	/// finish() if it was not called; errors are swallowed here (call finish() to see them).
	~Writer();
	Writer(const Writer &) = delete;
	Writer &operator=(const Writer &) = delete;

	/// Returns the new schema's id (1, 2, ...). Written to the data section at once.
	uint16_t add_schema(std::string name, std::string encoding, std::string data);
	/// Returns the new channel's id (0, 1, ...). `schema_id` 0 means no schema.
	uint16_t add_channel(uint16_t schema_id, std::string topic, std::string message_encoding,
			     std::map<std::string, std::string> metadata = {});
	/// A Metadata record (name and key/value pairs), indexed in the summary.
	void add_metadata(const std::string &name, const std::map<std::string, std::string> &values);
	/// Appends a message to the open chunk (sequence numbers count per channel); writes the chunk when it is
	/// full, unless `hold` (the caller has more of the same frame to add and calls maybe_flush() after the
	/// last, so a frame's messages share a chunk and a crash keeps or loses them together). Throws
	/// std::runtime_error on a failed write: the file then holds every chunk written before.
	void write(uint16_t channel_id, uint64_t log_time, uint64_t publish_time, std::span<const uint8_t> data,
		   bool hold = false);
	/// Writes the open chunk if it is full (by size or time span).
	void maybe_flush();
	/// Writes the open chunk now; `sync` then forces the file to the disk.
	void flush(bool sync = false);
	/// Writes the open chunk, Data End, the summary, the summary offsets and the footer. Idempotent.
	void finish();

	[[nodiscard]] uint64_t bytes_written() const { return offset_; }
	[[nodiscard]] uint64_t messages_written() const { return message_count_; }
	[[nodiscard]] uint64_t chunks_written() const { return chunk_indexes_.size(); }

private:
	struct ChunkIndex {
		uint64_t start_time, end_time, offset, length, index_length, records_size;
		std::map<uint16_t, uint64_t> index_offsets;
	};
	void write_bytes(const std::vector<uint8_t> &bytes);
	void write_chunk();

	std::string path_;
	WriterOptions options_;
	int fd_ = -1;
	bool finished_ = false;
	uint64_t offset_ = 0;	///< bytes in the file so far
	uint32_t data_crc_ = 0; ///< CRC-32 of every byte written before Data End
	std::vector<Schema> schemas_;
	std::vector<Channel> channels_;
	std::vector<uint32_t> sequences_;
	struct MetadataIndex {
		uint64_t offset, length;
		std::string name;
	};
	std::vector<MetadataIndex> metadata_index_;

	// The open chunk: its records, and per channel (log_time, offset in the records) for the message index.
	std::vector<uint8_t> chunk_;
	std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_index_entries_;
	uint64_t chunk_start_time_ = 0, chunk_end_time_ = 0;
	bool chunk_has_messages_ = false;
	std::vector<uint8_t> head_, tail_; ///< reused: a chunk's header fields and its message indexes

	std::vector<ChunkIndex> chunk_indexes_;
	std::map<uint16_t, uint64_t> channel_counts_;
	uint64_t message_count_ = 0, start_time_ = 0, end_time_ = 0;
};

/// One message as the reader hands it out; `data` stays valid until the next call to next().
struct MessageView {
	const Channel *channel = nullptr;
	uint32_t sequence = 0;
	uint64_t log_time = 0;
	uint64_t publish_time = 0;
	std::span<const uint8_t> data;
};

/// What a reader found, read front to back.
struct ReadReport {
	uint64_t messages = 0;	///< messages delivered
	uint64_t chunks = 0;	///< complete, valid chunks read
	bool clean_end = false; ///< Data End, a summary if any, the footer and the closing magic all read
	bool data_crc_checked = false;
	uint64_t cut_at_offset = 0; ///< where the first unreadable record starts (when not clean)
	uint64_t bytes_dropped = 0;
	std::string reason;
	[[nodiscard]] std::string describe() const;
};

/// What the summary section says, checked against the file: every chunk index must point at a chunk record
/// of that length, every message index at a Message Index record, the summary CRC must hold.
struct IndexCheck {
	bool present = false; ///< a footer with a summary was found
	bool valid = false;   ///< and everything below held
	uint64_t chunk_indexes = 0;
	uint64_t indexed_messages = 0; ///< entries in the message indexes the chunk indexes point at
	uint64_t statistics_messages = 0;
	std::vector<std::string> problems;
};

class Reader
{
public:
	/// Opens `path`, checks the magic and reads the Header. Throws std::runtime_error naming the path.
	explicit Reader(const std::string &path);
	~Reader();
	Reader(const Reader &) = delete;
	Reader &operator=(const Reader &) = delete;

	/// The next message in file order (inside and outside chunks). False at the end of the valid data:
	/// report() then says whether the file ended cleanly or where and why it was cut.
	bool next(MessageView &out);
	[[nodiscard]] const ReadReport &report() const { return report_; }

	[[nodiscard]] const std::string &profile() const { return profile_; }
	[[nodiscard]] const std::string &library() const { return library_; }
	[[nodiscard]] const std::map<uint16_t, Schema> &schemas() const { return schemas_; }
	[[nodiscard]] const std::map<uint16_t, Channel> &channels() const { return channels_; }
	[[nodiscard]] const std::vector<std::pair<std::string, std::map<std::string, std::string>>> &metadata() const
	{
		return metadata_;
	}
	/// Reads schemas and channels up to the first message without consuming it (they precede it).
	void read_definitions();

	/// Checks the summary and indexes from the footer (independent of next()).
	[[nodiscard]] IndexCheck check_index() const;

private:
	enum class Step { Message, Again, End };
	Step step(MessageView &out);
	bool read_exact(uint8_t *into, size_t size);
	bool fail(const std::string &reason, uint64_t at);
	void handle_definition(uint8_t opcode, std::span<const uint8_t> content);
	/// A Message record's content as a view; throws on a short record or an unknown channel.
	void parse_message(std::span<const uint8_t> content, MessageView &out) const;
	bool read_tail();

	std::string path_;
	std::FILE *file_ = nullptr;
	uint64_t file_size_ = 0;
	uint64_t offset_ = 0;
	uint32_t crc_ = 0; ///< CRC-32 of the bytes read so far (for Data End)
	std::string profile_, library_;
	std::map<uint16_t, Schema> schemas_;
	std::map<uint16_t, Channel> channels_;
	std::vector<std::pair<std::string, std::map<std::string, std::string>>> metadata_;
	std::vector<uint8_t> record_; ///< the current record's content
	std::vector<uint8_t> chunk_;  ///< the records of the chunk being walked
	size_t chunk_cursor_ = 0;
	bool in_chunk_ = false;
	bool done_ = false;
	bool pending_ = false; ///< read_definitions() stopped at a message not yet handed out
	MessageView pending_view_;
	ReadReport report_;
};

/// True when `path` begins with MCAP's magic (an unreadable or short file is not MCAP).
bool is_mcap_file(const std::string &path);

} // namespace stereod::drivers::mcap
