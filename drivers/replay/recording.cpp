#include "drivers/replay/recording.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <fcntl.h>
#include <stdexcept>
#include <sys/stat.h>
#include <unistd.h>

#include <nlohmann/json.hpp>
#include <zlib.h>

namespace stereod::drivers {
namespace {

constexpr char kMagic[8] = {'S', 'R', 'E', 'C', '\r', '\n', '\x1a', '\n'};
constexpr uint32_t kVersion = 1;
constexpr uint32_t kRecordMagic = 0x4d524653; // "SFRM" little-endian
constexpr size_t kRecordHeaderSize = 12;      // magic, payload length, payload CRC
constexpr uint32_t kMaxPayload = 1U << 30;

enum class ImageRole : uint8_t { Left = 0, Right = 1, Depth = 2, ObjectIds = 3 };

uint32_t crc32_of(const uint8_t *data, size_t size)
{
	return static_cast<uint32_t>(crc32(0L, data, static_cast<uInt>(size)));
}

template <typename T>
void put(std::vector<uint8_t> &out, const T &value)
{
	const auto *bytes = reinterpret_cast<const uint8_t *>(&value);
	out.insert(out.end(), bytes, bytes + sizeof(T));
}

template <typename T>
T get(const uint8_t *&cursor, const uint8_t *end)
{
	if (static_cast<size_t>(end - cursor) < sizeof(T))
		throw std::runtime_error("record shorter than its fields");
	T value;
	std::memcpy(&value, cursor, sizeof(T));
	cursor += sizeof(T);
	return value;
}

void put_image(std::vector<uint8_t> &out, ImageRole role, const cv::Mat &image)
{
	put<uint8_t>(out, static_cast<uint8_t>(role));
	put<uint8_t>(out, 0);
	put<uint16_t>(out, static_cast<uint16_t>(image.type()));
	put<uint32_t>(out, static_cast<uint32_t>(image.rows));
	put<uint32_t>(out, static_cast<uint32_t>(image.cols));
	const size_t row_bytes = static_cast<size_t>(image.cols) * image.elemSize();
	for (int y = 0; y < image.rows; ++y)
		out.insert(out.end(), image.ptr<uint8_t>(y), image.ptr<uint8_t>(y) + row_bytes);
}

} // namespace

RecordingHeader RecordingHeader::stamped_now(std::string source, std::string description, const FrameGeometry &geometry)
{
	RecordingHeader h{std::move(source), std::move(description), geometry, 0};
	h.created_unix_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
				    std::chrono::system_clock::now().time_since_epoch())
				    .count();
	return h;
}

std::string recording_header_json(const RecordingHeader &h)
{
	return nlohmann::json{{"source", h.source},
			      {"description", h.description},
			      {"width", h.geometry.width},
			      {"height", h.geometry.height},
			      {"format", to_string(h.geometry.format)},
			      {"stereo", h.geometry.stereo},
			      {"depth", h.geometry.depth},
			      {"truth", h.geometry.truth},
			      {"nominal_fps", h.geometry.nominal_fps},
			      {"created_unix_ns", h.created_unix_ns}}
		.dump();
}

RecordingHeader parse_recording_header(const std::string &json)
{
	RecordingHeader header;
	const auto j = nlohmann::json::parse(json);
	header.source = j.at("source").get<std::string>();
	header.description = j.value("description", "");
	// Sizes as 64-bit integers first: a float or a huge number converted straight to int is undefined.
	const auto side = [&j](const char *key) {
		const auto &v = j.at(key);
		if (!v.is_number_integer())
			throw std::runtime_error(std::string(key) + " is not an integer");
		const auto n = v.get<int64_t>();
		return static_cast<int>(std::clamp<int64_t>(n, -1, int64_t{1} << 30));
	};
	header.geometry.width = side("width");
	header.geometry.height = side("height");
	const auto format = j.at("format").get<std::string>();
	if (format == "mono8")
		header.geometry.format = PixelFormat::Mono8;
	else if (format == "bgr8")
		header.geometry.format = PixelFormat::Bgr8;
	else
		throw std::runtime_error("unknown pixel format '" + format + "'");
	header.geometry.stereo = j.at("stereo").get<bool>();
	header.geometry.depth = j.at("depth").get<bool>();
	header.geometry.truth = j.at("truth").get<bool>();
	header.geometry.nominal_fps =
		j.contains("nominal_fps") && j.at("nominal_fps").is_number() ? j.at("nominal_fps").get<double>() : 0.0;
	header.created_unix_ns = j.contains("created_unix_ns") && j.at("created_unix_ns").is_number_integer()
					 ? j.at("created_unix_ns").get<int64_t>()
					 : 0;
	// A reader's caller allocates frames of this geometry: refuse what no camera makes before it does.
	constexpr int kMaxSide = 16384;
	const auto &g = header.geometry;
	if (g.width < 1 || g.height < 1 || g.width > kMaxSide || g.height > kMaxSide)
		throw std::runtime_error("implausible image size " + std::to_string(g.width) + "x" +
					 std::to_string(g.height) + " (1 to " + std::to_string(kMaxSide) + " a side)");
	return header;
}

void encode_frame(const StereoFrame &frame, const FrameGeometry &geometry, std::vector<uint8_t> &out)
{
	put<uint64_t>(out, frame.sequence);
	put<int64_t>(out, frame.device_ns);
	put<int64_t>(out, frame.host_ns);
	put<int64_t>(out, frame.lr_skew_ns);
	put<uint8_t>(out, static_cast<uint8_t>(frame.status));
	const uint8_t images = static_cast<uint8_t>(1 + (geometry.stereo ? 1 : 0) + (geometry.depth ? 1 : 0) +
						    (geometry.truth ? 1 : 0));
	put<uint8_t>(out, images);
	put<uint16_t>(out, 0);
	if (geometry.truth) {
		for (double value : frame.truth.camera_pose)
			put<double>(out, value);
		put<uint32_t>(out, static_cast<uint32_t>(frame.truth.object_count));
		for (size_t i = 0; i < frame.truth.object_count; ++i) {
			const ObjectTruth &object = frame.truth.objects[i];
			put<uint16_t>(out, object.id);
			for (double v : object.position_m)
				put<double>(out, v);
			for (double v : object.velocity_mps)
				put<double>(out, v);
		}
	}
	put_image(out, ImageRole::Left, frame.left);
	if (geometry.stereo)
		put_image(out, ImageRole::Right, frame.right);
	if (geometry.depth)
		put_image(out, ImageRole::Depth, frame.depth);
	if (geometry.truth)
		put_image(out, ImageRole::ObjectIds, frame.truth.object_ids);
}

void decode_frame(const uint8_t *data, size_t size, const FrameGeometry &geometry, StereoFrame &into)
{
	const uint8_t *cursor = data;
	const uint8_t *end = data + size;
	into.sequence = get<uint64_t>(cursor, end);
	into.device_ns = get<int64_t>(cursor, end);
	into.host_ns = get<int64_t>(cursor, end);
	into.lr_skew_ns = get<int64_t>(cursor, end);
	const auto status = get<uint8_t>(cursor, end);
	if (status > static_cast<uint8_t>(FrameStatus::Corrupt))
		throw std::runtime_error("bad frame status");
	into.status = static_cast<FrameStatus>(status);
	const auto images = get<uint8_t>(cursor, end);
	(void)get<uint16_t>(cursor, end);
	into.truth.object_count = 0;
	if (geometry.truth) {
		for (double &value : into.truth.camera_pose)
			value = get<double>(cursor, end);
		const auto count = get<uint32_t>(cursor, end);
		if (count > FrameTruth::kMaxObjects)
			throw std::runtime_error("too many truth objects");
		for (uint32_t i = 0; i < count; ++i) {
			ObjectTruth &object = into.truth.objects[i];
			object.id = get<uint16_t>(cursor, end);
			for (double &v : object.position_m)
				v = get<double>(cursor, end);
			for (double &v : object.velocity_mps)
				v = get<double>(cursor, end);
		}
		into.truth.object_count = count;
	}
	for (uint8_t i = 0; i < images; ++i) {
		const auto role = get<uint8_t>(cursor, end);
		(void)get<uint8_t>(cursor, end);
		const auto type = get<uint16_t>(cursor, end);
		const auto rows = get<uint32_t>(cursor, end);
		const auto cols = get<uint32_t>(cursor, end);
		cv::Mat *target = role == 0   ? &into.left
				  : role == 1 ? &into.right
				  : role == 2 ? &into.depth
				  : role == 3 ? &into.truth.object_ids
					      : nullptr;
		if (!target || target->empty() || target->type() != type || target->rows != static_cast<int>(rows) ||
		    target->cols != static_cast<int>(cols))
			throw std::runtime_error("image does not match the header's geometry");
		const size_t row_bytes = static_cast<size_t>(cols) * target->elemSize();
		if (static_cast<size_t>(end - cursor) < row_bytes * rows)
			throw std::runtime_error("image data cut short");
		for (uint32_t y = 0; y < rows; ++y, cursor += row_bytes)
			std::memcpy(target->ptr<uint8_t>(static_cast<int>(y)), cursor, row_bytes);
	}
}

RecordingWriter::RecordingWriter(const std::string &path, const RecordingHeader &header)
	: path_(path), geometry_(header.geometry)
{
	fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_APPEND | O_CLOEXEC, 0644);
	if (fd_ < 0)
		throw std::runtime_error(path + ": cannot create recording: " + std::strerror(errno));
	const std::string json = recording_header_json(header);
	std::vector<uint8_t> head(kMagic, kMagic + sizeof(kMagic));
	put<uint32_t>(head, kVersion);
	put<uint32_t>(head, static_cast<uint32_t>(json.size()));
	head.insert(head.end(), json.begin(), json.end());
	put<uint32_t>(head, crc32_of(reinterpret_cast<const uint8_t *>(json.data()), json.size()));
	write_all(head.data(), head.size());
	::fdatasync(fd_);
}

RecordingWriter::~RecordingWriter()
{
	if (fd_ >= 0) {
		::fdatasync(fd_);
		::close(fd_);
	}
}

void RecordingWriter::write_all(const uint8_t *data, size_t size)
{
	while (size > 0) {
		const ssize_t n = ::write(fd_, data, size);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			throw std::runtime_error(path_ + ": write failed: " + std::strerror(errno));
		}
		data += n;
		size -= static_cast<size_t>(n);
		bytes_ += static_cast<uint64_t>(n);
	}
}

void RecordingWriter::append(const StereoFrame &frame, bool sync)
{
	buffer_.clear();
	buffer_.resize(kRecordHeaderSize); // filled in below, once the payload is known
	encode_frame(frame, geometry_, buffer_);
	const size_t payload = buffer_.size() - kRecordHeaderSize;
	const uint32_t header[3] = {kRecordMagic, static_cast<uint32_t>(payload),
				    crc32_of(buffer_.data() + kRecordHeaderSize, payload)};
	std::memcpy(buffer_.data(), header, sizeof(header));
	write_all(buffer_.data(), buffer_.size());
	if (sync)
		::fdatasync(fd_);
	++frames_;
}

std::string RecoveryReport::describe() const
{
	if (clean_end)
		return std::to_string(frames) + " frames, clean end";
	return std::to_string(frames) + " complete frames recovered; cut at byte " + std::to_string(cut_at_offset) +
	       ": " + reason + " (" + std::to_string(bytes_dropped) + " bytes dropped)";
}

RecordingReader::RecordingReader(const std::string &path) : path_(path)
{
	file_ = std::fopen(path.c_str(), "rb");
	if (!file_)
		throw std::runtime_error(path + ": cannot open recording: " + std::strerror(errno));
	// A refused file is closed here: the destructor does not run for a constructor that throws (each refused
	// recording leaked its FILE; fuzz_recording ran out of memory on them).
	try {
		read_header();
	} catch (...) {
		std::fclose(file_);
		file_ = nullptr;
		throw;
	}
}

void RecordingReader::read_header()
{
	const std::string &path = path_;
	struct stat st {
	};
	if (::fstat(::fileno(file_), &st) == 0)
		file_size_ = static_cast<uint64_t>(st.st_size);

	char magic[sizeof(kMagic)];
	uint32_t fields[2];
	if (std::fread(magic, 1, sizeof(magic), file_) != sizeof(magic) ||
	    std::memcmp(magic, kMagic, sizeof(kMagic)) != 0)
		throw std::runtime_error(path + ": not a stereod recording (bad magic)");
	if (std::fread(fields, sizeof(uint32_t), 2, file_) != 2)
		throw std::runtime_error(path + ": recording header is cut short");
	if (fields[0] != kVersion)
		throw std::runtime_error(path + ": recording version " + std::to_string(fields[0]) +
					 " is not supported (this build reads version " + std::to_string(kVersion) +
					 ")");
	if (fields[1] > (1U << 20))
		throw std::runtime_error(path + ": recording header is implausibly large");
	std::string json(fields[1], '\0');
	uint32_t crc = 0;
	if (std::fread(json.data(), 1, json.size(), file_) != json.size() || std::fread(&crc, 4, 1, file_) != 1)
		throw std::runtime_error(path + ": recording header is cut short");
	if (crc != crc32_of(reinterpret_cast<const uint8_t *>(json.data()), json.size()))
		throw std::runtime_error(path + ": recording header fails its CRC");
	try {
		header_ = parse_recording_header(json);
	} catch (const std::exception &e) {
		throw std::runtime_error(path + ": bad recording header: " + e.what());
	}
	offset_ = sizeof(kMagic) + 8 + json.size() + 4;
}

RecordingReader::~RecordingReader()
{
	if (file_)
		std::fclose(file_);
}

bool RecordingReader::fail(const std::string &reason)
{
	report_.clean_end = false;
	report_.cut_at_offset = offset_;
	report_.bytes_dropped = file_size_ > offset_ ? file_size_ - offset_ : 0;
	report_.reason = reason;
	done_ = true;
	return false;
}

bool RecordingReader::next(StereoFrame &into)
{
	if (done_)
		return false;
	uint32_t head[3];
	const size_t got = std::fread(head, 1, sizeof(head), file_);
	if (got == 0 && std::feof(file_)) {
		done_ = true;
		return false;
	}
	if (got != sizeof(head))
		return fail("record header cut short (" + std::to_string(got) + " of 12 bytes)");
	if (head[0] != kRecordMagic)
		return fail("no record marker");
	if (head[1] > kMaxPayload)
		return fail("implausible record length " + std::to_string(head[1]));
	// A length the rest of the file cannot hold is a cut (or a corrupt length): said before allocating it
	// (fuzz_recording ran out of memory on a 50 KB file claiming a record of hundreds of megabytes).
	const uint64_t after_head = offset_ + sizeof(head);
	const uint64_t left = file_size_ > after_head ? file_size_ - after_head : 0;
	if (file_size_ > 0 && head[1] > left)
		return fail("record cut short (" + std::to_string(left) + " of " + std::to_string(head[1]) + " bytes)");
	buffer_.resize(head[1]);
	const size_t payload = std::fread(buffer_.data(), 1, head[1], file_);
	if (payload != head[1])
		return fail("record cut short (" + std::to_string(payload) + " of " + std::to_string(head[1]) +
			    " bytes)");
	if (crc32_of(buffer_.data(), buffer_.size()) != head[2])
		return fail("record fails its CRC");

	try {
		decode_frame(buffer_.data(), buffer_.size(), header_.geometry, into);
	} catch (const std::exception &e) {
		return fail(std::string("record is malformed: ") + e.what());
	}
	offset_ += sizeof(head) + head[1];
	++report_.frames;
	return true;
}

} // namespace stereod::drivers
