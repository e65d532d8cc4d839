#include "drivers/replay/mcap.hpp"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <stdexcept>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <zlib.h>

namespace stereod::drivers::mcap {
namespace {

constexpr uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

enum Opcode : uint8_t {
	kHeader = 0x01,
	kFooter = 0x02,
	kSchema = 0x03,
	kChannel = 0x04,
	kMessage = 0x05,
	kChunk = 0x06,
	kMessageIndex = 0x07,
	kChunkIndex = 0x08,
	kAttachment = 0x09,
	kAttachmentIndex = 0x0A,
	kStatistics = 0x0B,
	kMetadata = 0x0C,
	kMetadataIndex = 0x0D,
	kSummaryOffset = 0x0E,
	kDataEnd = 0x0F,
};

constexpr size_t kRecordHead = 9;		   // opcode + u64 length
constexpr uint64_t kMaxRecord = uint64_t{1} << 32; // no record of ours comes near; a longer one is corrupt

uint32_t crc_update(uint32_t crc, const uint8_t *data, size_t size)
{
	while (size > 0) {
		const auto n = static_cast<uInt>(std::min<size_t>(size, 1U << 30));
		crc = static_cast<uint32_t>(crc32(crc, data, n));
		data += n;
		size -= n;
	}
	return crc;
}

// ---- serialisation (little-endian, as the specification says; the hosts we build for are little-endian)
static_assert(std::endian::native == std::endian::little, "MCAP fields are written as host integers");

template <typename T>
void put(std::vector<uint8_t> &out, T value)
{
	const auto *bytes = reinterpret_cast<const uint8_t *>(&value);
	out.insert(out.end(), bytes, bytes + sizeof(T));
}

void put_string(std::vector<uint8_t> &out, const std::string &s)
{
	put<uint32_t>(out, static_cast<uint32_t>(s.size()));
	out.insert(out.end(), s.begin(), s.end());
}

void put_string_map(std::vector<uint8_t> &out, const std::map<std::string, std::string> &m)
{
	std::vector<uint8_t> body;
	for (const auto &[k, v] : m) {
		put_string(body, k);
		put_string(body, v);
	}
	put<uint32_t>(out, static_cast<uint32_t>(body.size()));
	out.insert(out.end(), body.begin(), body.end());
}

/// Starts a record: opcode and a length patched by end_record().
size_t begin_record(std::vector<uint8_t> &out, uint8_t opcode)
{
	out.push_back(opcode);
	put<uint64_t>(out, 0);
	return out.size();
}

void end_record(std::vector<uint8_t> &out, size_t content_start)
{
	const uint64_t length = out.size() - content_start;
	std::memcpy(out.data() + content_start - 8, &length, 8);
}

std::vector<uint8_t> schema_record(const Schema &s)
{
	std::vector<uint8_t> out;
	const size_t at = begin_record(out, kSchema);
	put<uint16_t>(out, s.id);
	put_string(out, s.name);
	put_string(out, s.encoding);
	put_string(out, s.data);
	end_record(out, at);
	return out;
}

std::vector<uint8_t> channel_record(const Channel &c)
{
	std::vector<uint8_t> out;
	const size_t at = begin_record(out, kChannel);
	put<uint16_t>(out, c.id);
	put<uint16_t>(out, c.schema_id);
	put_string(out, c.topic);
	put_string(out, c.message_encoding);
	put_string_map(out, c.metadata);
	end_record(out, at);
	return out;
}

/// Reads fields from a record's content; every read is bounds-checked (a short record throws).
class Cursor
{
public:
	explicit Cursor(std::span<const uint8_t> bytes) : bytes_(bytes) {}
	template <typename T>
	T get()
	{
		need(sizeof(T));
		T value;
		std::memcpy(&value, bytes_.data() + at_, sizeof(T));
		at_ += sizeof(T);
		return value;
	}
	std::span<const uint8_t> bytes(uint64_t n)
	{
		need(n);
		auto out = bytes_.subspan(at_, static_cast<size_t>(n));
		at_ += static_cast<size_t>(n);
		return out;
	}
	std::string string()
	{
		const auto n = get<uint32_t>();
		const auto b = bytes(n);
		return {b.begin(), b.end()};
	}
	std::map<std::string, std::string> string_map()
	{
		const auto n = get<uint32_t>();
		Cursor inner(bytes(n));
		std::map<std::string, std::string> out;
		while (!inner.empty()) {
			auto k = inner.string();
			out[std::move(k)] = inner.string();
		}
		return out;
	}
	[[nodiscard]] bool empty() const { return at_ == bytes_.size(); }
	[[nodiscard]] size_t left() const { return bytes_.size() - at_; }
	[[nodiscard]] std::span<const uint8_t> rest() const { return bytes_.subspan(at_); }

private:
	void need(uint64_t n) const
	{
		if (n > bytes_.size() - at_)
			throw std::runtime_error("record shorter than its fields");
	}
	std::span<const uint8_t> bytes_;
	size_t at_ = 0;
};

Schema parse_schema(std::span<const uint8_t> content)
{
	Cursor c(content);
	Schema s;
	s.id = c.get<uint16_t>();
	s.name = c.string();
	s.encoding = c.string();
	s.data = c.string(); // uint32-prefixed bytes, same layout as a string
	return s;
}

Channel parse_channel(std::span<const uint8_t> content)
{
	Cursor c(content);
	Channel ch;
	ch.id = c.get<uint16_t>();
	ch.schema_id = c.get<uint16_t>();
	ch.topic = c.string();
	ch.message_encoding = c.string();
	ch.metadata = c.string_map();
	return ch;
}

} // namespace

// ============================================================================================== Writer

Writer::Writer(const std::string &path, WriterOptions options) : path_(path), options_(std::move(options))
{
	fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_APPEND | O_CLOEXEC, 0644);
	if (fd_ < 0)
		throw std::runtime_error(path + ": cannot create MCAP file: " + std::strerror(errno));
	std::vector<uint8_t> head(std::begin(kMagic), std::end(kMagic));
	const size_t at = begin_record(head, kHeader);
	put_string(head, options_.profile);
	put_string(head, options_.library);
	end_record(head, at);
	try {
		write_bytes(head);
	} catch (...) {
		::close(fd_);
		fd_ = -1;
		throw;
	}
	chunk_.reserve(options_.chunk_bytes + (1U << 16));
}

Writer::~Writer()
{
	try {
		finish();
	} catch (const std::exception &) {
		// The file keeps every chunk written before; finish() is where a caller sees the error.
	}
	if (fd_ >= 0)
		::close(fd_);
}

void Writer::write_bytes(const std::vector<uint8_t> &bytes)
{
	const uint8_t *data = bytes.data();
	size_t size = bytes.size();
	while (size > 0) {
		const ssize_t n = ::write(fd_, data, size);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			throw std::runtime_error(path_ + ": write failed: " + std::strerror(errno));
		}
		data_crc_ = crc_update(data_crc_, data, static_cast<size_t>(n));
		data += n;
		size -= static_cast<size_t>(n);
		offset_ += static_cast<uint64_t>(n);
	}
}

uint16_t Writer::add_schema(std::string name, std::string encoding, std::string data)
{
	Schema s{static_cast<uint16_t>(schemas_.size() + 1), std::move(name), std::move(encoding), std::move(data)};
	write_bytes(schema_record(s));
	schemas_.push_back(std::move(s));
	return schemas_.back().id;
}

uint16_t Writer::add_channel(uint16_t schema_id, std::string topic, std::string message_encoding,
			     std::map<std::string, std::string> metadata)
{
	if (schema_id > schemas_.size())
		throw std::invalid_argument("mcap: channel " + topic + " names an unknown schema");
	Channel c{static_cast<uint16_t>(channels_.size()), schema_id, std::move(topic), std::move(message_encoding),
		  std::move(metadata)};
	write_bytes(channel_record(c));
	channels_.push_back(std::move(c));
	sequences_.push_back(0);
	return channels_.back().id;
}

void Writer::add_metadata(const std::string &name, const std::map<std::string, std::string> &values)
{
	std::vector<uint8_t> out;
	const size_t at = begin_record(out, kMetadata);
	put_string(out, name);
	put_string_map(out, values);
	end_record(out, at);
	const uint64_t offset = offset_;
	write_bytes(out);
	metadata_index_.push_back({offset, out.size(), name});
}

void Writer::write(uint16_t channel_id, uint64_t log_time, uint64_t publish_time, std::span<const uint8_t> data,
		   bool hold)
{
	if (finished_)
		throw std::logic_error("mcap: write after finish");
	if (channel_id >= channels_.size())
		throw std::invalid_argument("mcap: unknown channel");
	const uint64_t at_in_chunk = chunk_.size();
	const size_t at = begin_record(chunk_, kMessage);
	put<uint16_t>(chunk_, channel_id);
	put<uint32_t>(chunk_, sequences_[channel_id]++);
	put<uint64_t>(chunk_, log_time);
	put<uint64_t>(chunk_, publish_time);
	chunk_.insert(chunk_.end(), data.begin(), data.end());
	end_record(chunk_, at);
	chunk_index_entries_[channel_id].emplace_back(log_time, at_in_chunk);
	if (!chunk_has_messages_) {
		chunk_start_time_ = chunk_end_time_ = log_time;
		chunk_has_messages_ = true;
	}
	chunk_start_time_ = std::min(chunk_start_time_, log_time);
	chunk_end_time_ = std::max(chunk_end_time_, log_time);
	if (message_count_ == 0)
		start_time_ = end_time_ = log_time;
	start_time_ = std::min(start_time_, log_time);
	end_time_ = std::max(end_time_, log_time);
	++message_count_;
	++channel_counts_[channel_id];
	if (!hold)
		maybe_flush();
}

void Writer::maybe_flush()
{
	if (chunk_.size() >= options_.chunk_bytes ||
	    (chunk_has_messages_ && chunk_end_time_ - chunk_start_time_ >= static_cast<uint64_t>(options_.chunk_ns)))
		write_chunk();
}

void Writer::flush(bool sync)
{
	write_chunk();
	if (sync)
		::fdatasync(fd_);
}

void Writer::write_chunk()
{
	if (chunk_.empty())
		return;
	const uint32_t records_crc = crc_update(0, chunk_.data(), chunk_.size());
	head_.clear();
	const std::string compression; // none: see the header comment
	const uint64_t content = 8 + 8 + 8 + 4 + (4 + compression.size()) + 8 + chunk_.size();
	head_.push_back(kChunk);
	put<uint64_t>(head_, content);
	put<uint64_t>(head_, chunk_has_messages_ ? chunk_start_time_ : 0);
	put<uint64_t>(head_, chunk_has_messages_ ? chunk_end_time_ : 0);
	put<uint64_t>(head_, chunk_.size());
	put<uint32_t>(head_, records_crc);
	put_string(head_, compression);
	put<uint64_t>(head_, chunk_.size());

	ChunkIndex index{};
	index.start_time = chunk_has_messages_ ? chunk_start_time_ : 0;
	index.end_time = chunk_has_messages_ ? chunk_end_time_ : 0;
	index.offset = offset_;
	index.length = kRecordHead + content;
	index.records_size = chunk_.size();
	tail_.clear();
	for (auto &[channel, entries] : chunk_index_entries_) {
		if (entries.empty())
			continue;
		// Readers binary-search the index by time: sorted by log time (stable, so file order breaks ties).
		std::stable_sort(entries.begin(), entries.end(),
				 [](const auto &a, const auto &b) { return a.first < b.first; });
		index.index_offsets[channel] = index.offset + index.length + tail_.size();
		const size_t at = begin_record(tail_, kMessageIndex);
		put<uint16_t>(tail_, channel);
		put<uint32_t>(tail_, static_cast<uint32_t>(entries.size() * 16));
		for (const auto &[time, offset] : entries) {
			put<uint64_t>(tail_, time);
			put<uint64_t>(tail_, offset);
		}
		end_record(tail_, at);
	}
	index.index_length = tail_.size();

	// One writev: on an O_APPEND file a crash leaves the chunk whole or cut, never interleaved.
	iovec parts[3] = {{head_.data(), head_.size()}, {chunk_.data(), chunk_.size()}, {tail_.data(), tail_.size()}};
	size_t total = head_.size() + chunk_.size() + tail_.size();
	size_t done = 0;
	while (done < total) {
		// Skip what went out already (a short writev is rare but legal).
		iovec rest[3];
		int count = 0;
		size_t skip = done;
		for (const auto &p : parts) {
			if (skip >= p.iov_len) {
				skip -= p.iov_len;
				continue;
			}
			rest[count++] = {static_cast<uint8_t *>(p.iov_base) + skip, p.iov_len - skip};
			skip = 0;
		}
		const ssize_t n = ::writev(fd_, rest, count);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			throw std::runtime_error(path_ + ": write failed: " + std::strerror(errno));
		}
		done += static_cast<size_t>(n);
	}
	for (const auto &p : parts)
		data_crc_ = crc_update(data_crc_, static_cast<const uint8_t *>(p.iov_base), p.iov_len);
	offset_ += total;
	if (options_.sync)
		::fdatasync(fd_);
	chunk_indexes_.push_back(std::move(index));
	chunk_.clear();
	for (auto &[channel, entries] : chunk_index_entries_)
		entries.clear();
	chunk_has_messages_ = false;
}

void Writer::finish()
{
	if (finished_ || fd_ < 0)
		return;
	finished_ = true;
	write_chunk();

	std::vector<uint8_t> out;
	size_t at = begin_record(out, kDataEnd);
	put<uint32_t>(out, data_crc_);
	end_record(out, at);
	write_bytes(out);

	// The summary: groups of records of one opcode, each located by a Summary Offset record.
	const uint64_t summary_start = offset_;
	std::vector<uint8_t> summary;
	std::vector<std::tuple<uint8_t, uint64_t, uint64_t>> groups;
	const auto group = [&](uint8_t opcode, auto &&emit) {
		const size_t before = summary.size();
		emit();
		if (summary.size() > before)
			groups.emplace_back(opcode, summary_start + before, summary.size() - before);
	};
	group(kSchema, [&] {
		for (const auto &s : schemas_) {
			const auto r = schema_record(s);
			summary.insert(summary.end(), r.begin(), r.end());
		}
	});
	group(kChannel, [&] {
		for (const auto &c : channels_) {
			const auto r = channel_record(c);
			summary.insert(summary.end(), r.begin(), r.end());
		}
	});
	group(kChunkIndex, [&] {
		for (const auto &ci : chunk_indexes_) {
			at = begin_record(summary, kChunkIndex);
			put<uint64_t>(summary, ci.start_time);
			put<uint64_t>(summary, ci.end_time);
			put<uint64_t>(summary, ci.offset);
			put<uint64_t>(summary, ci.length);
			put<uint32_t>(summary, static_cast<uint32_t>(ci.index_offsets.size() * 10));
			for (const auto &[channel, offset] : ci.index_offsets) {
				put<uint16_t>(summary, channel);
				put<uint64_t>(summary, offset);
			}
			put<uint64_t>(summary, ci.index_length);
			put_string(summary, "");
			put<uint64_t>(summary, ci.records_size); // compressed = uncompressed: no compression
			put<uint64_t>(summary, ci.records_size);
			end_record(summary, at);
		}
	});
	group(kMetadataIndex, [&] {
		for (size_t i = 0; i < metadata_index_.size(); ++i) {
			at = begin_record(summary, kMetadataIndex);
			put<uint64_t>(summary, metadata_index_[i].offset);
			put<uint64_t>(summary, metadata_index_[i].length);
			put_string(summary, metadata_index_[i].name);
			end_record(summary, at);
		}
	});
	group(kStatistics, [&] {
		at = begin_record(summary, kStatistics);
		put<uint64_t>(summary, message_count_);
		put<uint16_t>(summary, static_cast<uint16_t>(schemas_.size()));
		put<uint32_t>(summary, static_cast<uint32_t>(channels_.size()));
		put<uint32_t>(summary, 0); // attachments
		put<uint32_t>(summary, static_cast<uint32_t>(metadata_index_.size()));
		put<uint32_t>(summary, static_cast<uint32_t>(chunk_indexes_.size()));
		put<uint64_t>(summary, message_count_ > 0 ? start_time_ : 0);
		put<uint64_t>(summary, message_count_ > 0 ? end_time_ : 0);
		put<uint32_t>(summary, static_cast<uint32_t>(channel_counts_.size() * 10));
		for (const auto &[channel, count] : channel_counts_) {
			put<uint16_t>(summary, channel);
			put<uint64_t>(summary, count);
		}
		end_record(summary, at);
	});
	const uint64_t summary_offset_start = summary_start + summary.size();
	for (const auto &[opcode, start, length] : groups) {
		at = begin_record(summary, kSummaryOffset);
		summary.push_back(opcode);
		put<uint64_t>(summary, start);
		put<uint64_t>(summary, length);
		end_record(summary, at);
	}
	// The footer; its CRC covers the summary and summary offsets and the footer up to summary_offset_start.
	summary.push_back(kFooter);
	put<uint64_t>(summary, 20);
	put<uint64_t>(summary, summary_start);
	put<uint64_t>(summary, summary_offset_start);
	put<uint32_t>(summary, crc_update(0, summary.data(), summary.size()));
	summary.insert(summary.end(), std::begin(kMagic), std::end(kMagic));
	write_bytes(summary);
	::fdatasync(fd_);
}

// ============================================================================================== Reader

bool is_mcap_file(const std::string &path)
{
	std::FILE *file = std::fopen(path.c_str(), "rb");
	if (!file)
		return false;
	uint8_t magic[sizeof(kMagic)] = {};
	const bool mcap = std::fread(magic, 1, sizeof(magic), file) == sizeof(magic) &&
			  std::memcmp(magic, kMagic, sizeof(kMagic)) == 0;
	std::fclose(file);
	return mcap;
}

std::string ReadReport::describe() const
{
	std::string s = std::to_string(messages) + " messages in " + std::to_string(chunks) + " chunks";
	if (clean_end)
		return s + ", clean end" + (data_crc_checked ? " (data CRC ok)" : "");
	return s + " recovered; cut at byte " + std::to_string(cut_at_offset) + ": " + reason + " (" +
	       std::to_string(bytes_dropped) + " bytes dropped)";
}

Reader::Reader(const std::string &path) : path_(path)
{
	file_ = std::fopen(path.c_str(), "rb");
	if (!file_)
		throw std::runtime_error(path + ": cannot open: " + std::strerror(errno));
	try {
		struct stat st {
		};
		if (::fstat(::fileno(file_), &st) == 0)
			file_size_ = static_cast<uint64_t>(st.st_size);
		uint8_t magic[8];
		if (!read_exact(magic, 8) || std::memcmp(magic, kMagic, 8) != 0)
			throw std::runtime_error(path + ": not an MCAP file (bad magic)");
		uint8_t head[kRecordHead];
		if (!read_exact(head, kRecordHead) || head[0] != kHeader)
			throw std::runtime_error(path + ": MCAP header record missing");
		uint64_t length;
		std::memcpy(&length, head + 1, 8);
		if (length > 1U << 20 || length > file_size_ - offset_)
			throw std::runtime_error(path + ": MCAP header record is implausible");
		record_.resize(length);
		if (!read_exact(record_.data(), record_.size()))
			throw std::runtime_error(path + ": MCAP header record cut short");
		Cursor c(record_);
		profile_ = c.string();
		library_ = c.string();
	} catch (const std::runtime_error &e) {
		std::fclose(file_);
		file_ = nullptr;
		const std::string what = e.what();
		throw std::runtime_error(what.rfind(path, 0) == 0 ? what : path + ": bad MCAP header: " + what);
	}
}

Reader::~Reader()
{
	if (file_)
		std::fclose(file_);
}

bool Reader::read_exact(uint8_t *into, size_t size)
{
	const size_t got = std::fread(into, 1, size, file_);
	crc_ = crc_update(crc_, into, got);
	offset_ += got;
	return got == size;
}

bool Reader::fail(const std::string &reason, uint64_t at)
{
	report_.clean_end = false;
	report_.cut_at_offset = at;
	report_.bytes_dropped = file_size_ > at ? file_size_ - at : 0;
	report_.reason = reason;
	done_ = true;
	in_chunk_ = false;
	return false;
}

void Reader::handle_definition(uint8_t opcode, std::span<const uint8_t> content)
{
	if (opcode == kSchema) {
		Schema s = parse_schema(content);
		if (s.id != 0)
			schemas_[s.id] = std::move(s);
	} else if (opcode == kChannel) {
		Channel c = parse_channel(content);
		channels_[c.id] = std::move(c);
	} else if (opcode == kMetadata) {
		Cursor c(content);
		auto name = c.string();
		metadata_.emplace_back(std::move(name), c.string_map());
	}
}

void Reader::parse_message(std::span<const uint8_t> content, MessageView &out) const
{
	Cursor m(content);
	const auto channel = m.get<uint16_t>();
	const auto it = channels_.find(channel);
	if (it == channels_.end())
		throw std::runtime_error("message on channel " + std::to_string(channel) +
					 " before its Channel record");
	out.channel = &it->second;
	out.sequence = m.get<uint32_t>();
	out.log_time = m.get<uint64_t>();
	out.publish_time = m.get<uint64_t>();
	out.data = m.rest();
}

bool Reader::next(MessageView &out)
{
	if (pending_) {
		pending_ = false;
		out = pending_view_;
		++report_.messages;
		return true;
	}
	for (;;) {
		const Step s = step(out);
		if (s == Step::Message) {
			++report_.messages;
			return true;
		}
		if (s == Step::End)
			return false;
	}
}

void Reader::read_definitions()
{
	if (pending_ || done_)
		return;
	for (;;) {
		const Step s = step(pending_view_);
		if (s == Step::Message) {
			pending_ = true;
			return;
		}
		if (s == Step::End)
			return;
	}
}

Reader::Step Reader::step(MessageView &out)
{
	if (done_)
		return Step::End;
	try {
		if (in_chunk_) {
			if (chunk_cursor_ >= chunk_.size()) {
				in_chunk_ = false;
				++report_.chunks;
				return Step::Again;
			}
			// The chunk passed its CRC, so a malformed record inside is a writer's bug, still refused.
			Cursor c(std::span<const uint8_t>(chunk_).subspan(chunk_cursor_));
			const auto opcode = c.get<uint8_t>();
			const auto length = c.get<uint64_t>();
			const auto content = c.bytes(length);
			chunk_cursor_ += kRecordHead + static_cast<size_t>(length);
			if (opcode == kMessage) {
				parse_message(content, out);
				return Step::Message;
			}
			handle_definition(opcode, content);
			return Step::Again;
		}

		const uint64_t at = offset_;
		const uint32_t crc_before = crc_; // of every byte before this record (Data End's CRC)
		uint8_t head[kRecordHead];
		const size_t got = std::fread(head, 1, kRecordHead, file_);
		if (got == 0 && std::feof(file_)) {
			fail("the file ends without Data End and footer (the writer did not finish)", at);
			return Step::End;
		}
		if (got != kRecordHead) {
			fail("record header cut short (" + std::to_string(got) + " of 9 bytes)", at);
			return Step::End;
		}
		crc_ = crc_update(crc_, head, kRecordHead);
		offset_ += kRecordHead;
		const uint8_t opcode = head[0];
		uint64_t length;
		std::memcpy(&length, head + 1, 8);
		const uint64_t left = file_size_ > offset_ ? file_size_ - offset_ : 0;
		if (opcode == 0) {
			fail("opcode 0 (not a record)", at);
			return Step::End;
		}
		if (length > left) {
			fail("record cut short (" + std::to_string(left) + " of " + std::to_string(length) + " bytes)",
			     at);
			return Step::End;
		}
		if (length > kMaxRecord) {
			fail("implausible record length " + std::to_string(length), at);
			return Step::End;
		}
		record_.resize(static_cast<size_t>(length));
		if (!read_exact(record_.data(), record_.size())) {
			fail("record cut short", at);
			return Step::End;
		}
		const std::span<const uint8_t> content(record_);
		switch (opcode) {
		case kMessage:
			parse_message(content, out); // a malformed one is caught below and ends the read here
			return Step::Message;
		case kChunk: {
			Cursor c(content);
			(void)c.get<uint64_t>(); // start time
			(void)c.get<uint64_t>(); // end time
			const auto uncompressed_size = c.get<uint64_t>();
			const auto uncompressed_crc = c.get<uint32_t>();
			const auto compression = c.string();
			const auto records_size = c.get<uint64_t>();
			const auto records = c.bytes(records_size);
			if (!compression.empty()) {
				fail("chunk compressed with '" + compression +
					     "' (this reader reads uncompressed chunks, as stereod writes them)",
				     at);
				return Step::End;
			}
			if (uncompressed_size != records_size) {
				fail("chunk sizes disagree", at);
				return Step::End;
			}
			if (uncompressed_crc != 0 &&
			    crc_update(0, records.data(), records.size()) != uncompressed_crc) {
				fail("chunk fails its CRC", at);
				return Step::End;
			}
			chunk_.assign(records.begin(), records.end());
			chunk_cursor_ = 0;
			in_chunk_ = true;
			return Step::Again;
		}
		case kDataEnd: {
			Cursor c(content);
			const auto expected = c.get<uint32_t>();
			if (expected != 0) {
				if (expected != crc_before) {
					fail("data section fails its CRC", at);
					return Step::End;
				}
				report_.data_crc_checked = true;
			}
			if (read_tail()) {
				report_.clean_end = true;
				done_ = true;
			}
			return Step::End;
		}
		case kFooter:
			// A footer without Data End (allowed: the data section then simply ends here).
			report_.clean_end = true;
			done_ = true;
			return Step::End;
		default:
			handle_definition(opcode, content);
			return Step::Again;
		}
	} catch (const std::exception &e) {
		fail(std::string("malformed record: ") + e.what(), offset_);
		return Step::End;
	}
}

bool Reader::read_tail()
{
	// The summary and summary offsets are skipped here (check_index() reads them from the footer); what
	// matters for a clean end is that the footer and the closing magic are there.
	for (;;) {
		const uint64_t at = offset_;
		uint8_t head[kRecordHead];
		if (!read_exact(head, kRecordHead))
			return fail("summary cut short (no footer)", at);
		uint64_t length;
		std::memcpy(&length, head + 1, 8);
		const uint64_t left = file_size_ > offset_ ? file_size_ - offset_ : 0;
		if (length > left || length > kMaxRecord)
			return fail("summary record cut short", at);
		record_.resize(static_cast<size_t>(length));
		if (!read_exact(record_.data(), record_.size()))
			return fail("summary record cut short", at);
		if (head[0] != kFooter)
			continue;
		uint8_t magic[8];
		if (!read_exact(magic, 8) || std::memcmp(magic, kMagic, 8) != 0)
			return fail("no closing magic after the footer", offset_);
		return true;
	}
}

IndexCheck Reader::check_index() const
{
	IndexCheck check;
	const int fd = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
	if (fd < 0) {
		check.problems.push_back(std::string("cannot open: ") + std::strerror(errno));
		return check;
	}
	const auto read_at = [fd](uint64_t offset, size_t size, std::vector<uint8_t> &into) {
		into.resize(size);
		size_t done = 0;
		while (done < size) {
			const ssize_t n =
				::pread(fd, into.data() + done, size - done, static_cast<off_t>(offset + done));
			if (n <= 0)
				return false;
			done += static_cast<size_t>(n);
		}
		return true;
	};
	const auto problem = [&check](std::string what) { check.problems.push_back(std::move(what)); };
	const auto done = [&]() {
		::close(fd);
		check.valid = check.problems.empty();
		return check;
	};
	std::vector<uint8_t> buf;
	constexpr uint64_t kFooterRecord = kRecordHead + 20;
	if (file_size_ < 8 + kFooterRecord + 8 || !read_at(file_size_ - 8 - kFooterRecord, kFooterRecord + 8, buf) ||
	    buf[0] != kFooter || std::memcmp(buf.data() + kFooterRecord, kMagic, 8) != 0) {
		problem("no footer at the end of the file (a cut file has no summary; it is read front to back)");
		return done();
	}
	const uint64_t footer_at = file_size_ - 8 - kFooterRecord;
	uint64_t summary_start, summary_offset_start;
	uint32_t summary_crc;
	std::memcpy(&summary_start, buf.data() + 9, 8);
	std::memcpy(&summary_offset_start, buf.data() + 17, 8);
	std::memcpy(&summary_crc, buf.data() + 25, 4);
	if (summary_start == 0) {
		problem("the footer points at no summary");
		return done();
	}
	check.present = true;
	if (summary_start > footer_at || summary_offset_start > footer_at ||
	    (summary_offset_start != 0 && summary_offset_start < summary_start)) {
		problem("the footer's summary offsets lie outside the file");
		return done();
	}
	// The summary CRC covers the summary, the summary offsets and the footer up to summary_offset_start.
	std::vector<uint8_t> summary;
	if (!read_at(summary_start, static_cast<size_t>(footer_at + kRecordHead + 16 - summary_start), summary)) {
		problem("summary unreadable");
		return done();
	}
	if (summary_crc != 0 && crc_update(0, summary.data(), summary.size()) != summary_crc)
		problem("summary fails its CRC");
	const uint64_t records_end = (summary_offset_start != 0 ? summary_offset_start : footer_at) - summary_start;
	try {
		Cursor c(std::span<const uint8_t>(summary).first(static_cast<size_t>(records_end)));
		while (!c.empty()) {
			const auto opcode = c.get<uint8_t>();
			const auto length = c.get<uint64_t>();
			Cursor r(c.bytes(length));
			if (opcode == kStatistics) {
				check.statistics_messages = r.get<uint64_t>();
				continue;
			}
			if (opcode != kChunkIndex)
				continue;
			++check.chunk_indexes;
			(void)r.get<uint64_t>();
			(void)r.get<uint64_t>();
			const auto chunk_offset = r.get<uint64_t>();
			const auto chunk_length = r.get<uint64_t>();
			Cursor offsets(r.bytes(r.get<uint32_t>()));
			const std::string where = "chunk index at " + std::to_string(chunk_offset);
			std::vector<uint8_t> head;
			if (!read_at(chunk_offset, kRecordHead, head) || head[0] != kChunk) {
				problem(where + ": no chunk record there");
				continue;
			}
			uint64_t length_there;
			std::memcpy(&length_there, head.data() + 1, 8);
			if (length_there + kRecordHead != chunk_length)
				problem(where + ": chunk length differs from the index");
			while (!offsets.empty()) {
				const auto channel = offsets.get<uint16_t>();
				const auto index_offset = offsets.get<uint64_t>();
				std::vector<uint8_t> mi;
				if (!read_at(index_offset, kRecordHead + 6, mi) || mi[0] != kMessageIndex) {
					problem(where + ": no message index at " + std::to_string(index_offset));
					continue;
				}
				uint16_t channel_there;
				uint32_t bytes;
				std::memcpy(&channel_there, mi.data() + 9, 2);
				std::memcpy(&bytes, mi.data() + 11, 4);
				if (channel_there != channel)
					problem(where + ": message index for the wrong channel");
				check.indexed_messages += bytes / 16;
			}
		}
	} catch (const std::exception &e) {
		problem(std::string("malformed summary: ") + e.what());
	}
	if (check.indexed_messages != check.statistics_messages)
		problem("the message indexes hold " + std::to_string(check.indexed_messages) +
			" entries, the statistics count " + std::to_string(check.statistics_messages) + " messages");
	return done();
}

} // namespace stereod::drivers::mcap
