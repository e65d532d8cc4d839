#include "drivers/v4l2/v4l2_device.hpp"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include "core/clock.hpp"

namespace stereod::drivers::v4l2 {
namespace {

/// ioctl, retried when a signal interrupts it.
int xioctl(int fd, unsigned long request, void *arg)
{
	int r = 0;
	do {
		r = ::ioctl(fd, request, arg);
	} while (r < 0 && errno == EINTR);
	return r;
}

std::string errno_text()
{
	return std::strerror(errno);
}

/// The frame sizes and rates a device offers for one format, as text.
std::string sizes_text(int fd, uint32_t fourcc)
{
	std::string out;
	v4l2_frmsizeenum size{};
	size.pixel_format = fourcc;
	for (size.index = 0; xioctl(fd, VIDIOC_ENUM_FRAMESIZES, &size) == 0; ++size.index) {
		if (size.type != V4L2_FRMSIZE_TYPE_DISCRETE) {
			out += " " + std::to_string(size.stepwise.min_width) + "x" +
			       std::to_string(size.stepwise.min_height) + ".." +
			       std::to_string(size.stepwise.max_width) + "x" + std::to_string(size.stepwise.max_height);
			break;
		}
		out += " " + std::to_string(size.discrete.width) + "x" + std::to_string(size.discrete.height);
		v4l2_frmivalenum interval{};
		interval.pixel_format = fourcc;
		interval.width = size.discrete.width;
		interval.height = size.discrete.height;
		if (xioctl(fd, VIDIOC_ENUM_FRAMEINTERVALS, &interval) == 0 &&
		    interval.type == V4L2_FRMIVAL_TYPE_DISCRETE && interval.discrete.numerator > 0) {
			char rate[32];
			std::snprintf(rate, sizeof(rate), "@%.4g",
				      static_cast<double>(interval.discrete.denominator) / interval.discrete.numerator);
			out += rate;
		}
	}
	return out;
}

std::string formats_text(int fd)
{
	std::string out;
	v4l2_fmtdesc desc{};
	desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
	for (desc.index = 0; xioctl(fd, VIDIOC_ENUM_FMT, &desc) == 0; ++desc.index)
		out += (out.empty() ? "" : ", ") + fourcc_text(desc.pixelformat);
	return out;
}

} // namespace

std::string fourcc_text(uint32_t fourcc)
{
	std::string s(4, ' ');
	for (int i = 0; i < 4; ++i)
		s[static_cast<size_t>(i)] = static_cast<char>((fourcc >> (8 * i)) & 0xff);
	while (!s.empty() && s.back() == ' ')
		s.pop_back();
	return s;
}

uint32_t fourcc_from(const std::string &name)
{
	if (name.empty() || name.size() > 4)
		throw SourceError("v4l2.pixel_format = \"" + name +
				  "\": a fourcc has one to four characters (YUYV, GREY, MJPG)");
	std::string padded = name;
	padded.resize(4, ' ');
	return v4l2_fourcc(padded[0], padded[1], padded[2], padded[3]);
}

std::string control_key(const char *name)
{
	std::string key;
	for (const char *p = name; *p; ++p) {
		const auto c = static_cast<unsigned char>(*p);
		if (std::isalnum(c))
			key.push_back(static_cast<char>(std::tolower(c)));
		else if (!key.empty() && key.back() != '_')
			key.push_back('_');
	}
	while (!key.empty() && key.back() == '_')
		key.pop_back();
	return key;
}

V4l2Device::V4l2Device(const std::string &path, const V4l2Config &config) : path_(path)
{
	fd_ = ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
	if (fd_ < 0) {
		std::string found;
		std::error_code ec;
		for (const auto &entry : std::filesystem::directory_iterator("/dev", ec))
			if (entry.path().filename().string().rfind("video", 0) == 0)
				found += (found.empty() ? "" : ", ") + entry.path().string();
		throw SourceError(path + ": cannot open (" + errno_text() +
				  "); video devices here: " + (found.empty() ? "none" : found));
	}
	try {
		configure(config);
	} catch (...) {
		close();
		throw;
	}
}

V4l2Device::~V4l2Device()
{
	close();
}

void V4l2Device::close() noexcept
{
	if (fd_ < 0)
		return;
	if (streaming_) {
		v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
		xioctl(fd_, VIDIOC_STREAMOFF, &type);
	}
	for (const auto &mapping : buffers_)
		::munmap(mapping.start, mapping.length);
	buffers_.clear();
	::close(fd_);
	fd_ = -1;
}

void V4l2Device::configure(const V4l2Config &config)
{
	v4l2_capability cap{};
	if (xioctl(fd_, VIDIOC_QUERYCAP, &cap) != 0)
		throw SourceError(path_ + ": not a V4L2 device (" + errno_text() + ")");
	const uint32_t caps = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
	if (!(caps & V4L2_CAP_VIDEO_CAPTURE))
		throw SourceError(path_ + ": " + reinterpret_cast<const char *>(cap.card) +
				  " is not a video capture device (a metadata or output node?)");
	if (!(caps & V4L2_CAP_STREAMING))
		throw SourceError(path_ + ": the driver does not support streaming I/O");
	description_ = std::string(reinterpret_cast<const char *>(cap.card)) + " (" + path_ + ", " +
		       reinterpret_cast<const char *>(cap.driver) + ")";

	v4l2_format format{};
	format.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
	if (xioctl(fd_, VIDIOC_G_FMT, &format) != 0)
		throw SourceError(path_ + ": VIDIOC_G_FMT: " + errno_text());
	if (config.width > 0)
		format.fmt.pix.width = static_cast<uint32_t>(config.width);
	if (config.height > 0)
		format.fmt.pix.height = static_cast<uint32_t>(config.height);
	if (!config.pixel_format.empty())
		format.fmt.pix.pixelformat = fourcc_from(config.pixel_format);
	format.fmt.pix.field = V4L2_FIELD_NONE;
	if (xioctl(fd_, VIDIOC_S_FMT, &format) != 0)
		throw SourceError(path_ + ": VIDIOC_S_FMT " + config.pixel_format + " " + std::to_string(config.width) +
				  "x" + std::to_string(config.height) + ": " + errno_text());
	if (!config.pixel_format.empty() && format.fmt.pix.pixelformat != fourcc_from(config.pixel_format))
		throw SourceError(path_ + ": v4l2.pixel_format = \"" + config.pixel_format +
				  "\" is not offered (the driver chose " + fourcc_text(format.fmt.pix.pixelformat) +
				  "; it offers " + formats_text(fd_) + ")");
	if ((config.width > 0 && format.fmt.pix.width != static_cast<uint32_t>(config.width)) ||
	    (config.height > 0 && format.fmt.pix.height != static_cast<uint32_t>(config.height)))
		throw SourceError(path_ + ": v4l2.width x height = " + std::to_string(config.width) + "x" +
				  std::to_string(config.height) + " is not offered for " +
				  fourcc_text(format.fmt.pix.pixelformat) + " (the driver chose " +
				  std::to_string(format.fmt.pix.width) + "x" + std::to_string(format.fmt.pix.height) +
				  "; sizes:" + sizes_text(fd_, format.fmt.pix.pixelformat) + ")");
	width_ = static_cast<int>(format.fmt.pix.width);
	height_ = static_cast<int>(format.fmt.pix.height);
	fourcc_ = format.fmt.pix.pixelformat;
	bytes_per_line_ = format.fmt.pix.bytesperline;

	v4l2_streamparm parm{};
	parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
	if (config.fps > 0) {
		parm.parm.capture.timeperframe.numerator = 1000;
		parm.parm.capture.timeperframe.denominator = static_cast<uint32_t>(config.fps * 1000 + 0.5);
		if (xioctl(fd_, VIDIOC_S_PARM, &parm) != 0)
			spdlog::warn("v4l2: {}: cannot set {} fps (VIDIOC_S_PARM: {})", path_, config.fps,
				     errno_text());
	}
	if (xioctl(fd_, VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator > 0)
		fps_ = static_cast<double>(parm.parm.capture.timeperframe.denominator) /
		       parm.parm.capture.timeperframe.numerator;
	if (config.fps > 0 && std::abs(fps_ - config.fps) > 0.01 * config.fps)
		spdlog::warn("v4l2: {}: asked for {} fps, the driver runs at {:.3g}", path_, config.fps, fps_);
	set_controls(config.controls);

	v4l2_requestbuffers request{};
	request.count = static_cast<uint32_t>(config.buffers);
	request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
	request.memory = V4L2_MEMORY_MMAP;
	if (xioctl(fd_, VIDIOC_REQBUFS, &request) != 0 || request.count < 2)
		throw SourceError(path_ + ": cannot get mmap buffers (VIDIOC_REQBUFS: " + errno_text() + ")");
	for (uint32_t i = 0; i < request.count; ++i) {
		v4l2_buffer buffer{};
		buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
		buffer.memory = V4L2_MEMORY_MMAP;
		buffer.index = i;
		if (xioctl(fd_, VIDIOC_QUERYBUF, &buffer) != 0)
			throw SourceError(path_ + ": VIDIOC_QUERYBUF: " + errno_text());
		void *start = ::mmap(nullptr, buffer.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buffer.m.offset);
		if (start == MAP_FAILED)
			throw SourceError(path_ + ": mmap: " + errno_text());
		buffers_.push_back({start, buffer.length});
		if (xioctl(fd_, VIDIOC_QBUF, &buffer) != 0)
			throw SourceError(path_ + ": VIDIOC_QBUF: " + errno_text());
	}
	spdlog::info("v4l2: {}: {}x{} {} at {:.3g} fps, {} mmap buffers", description_, width_, height_,
		     fourcc_text(fourcc_), fps_, buffers_.size());
}

void V4l2Device::start()
{
	if (streaming_)
		return;
	v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
	if (xioctl(fd_, VIDIOC_STREAMON, &type) != 0)
		throw SourceError(path_ + ": VIDIOC_STREAMON: " + errno_text());
	streaming_ = true;
}

void V4l2Device::set_controls(const std::vector<std::string> &controls)
{
	for (const auto &setting : controls) {
		const auto eq = setting.find('=');
		if (eq == std::string::npos)
			throw SourceError(path_ + ": v4l2.controls entry '" + setting + "' is not name=value");
		const std::string name = setting.substr(0, eq);
		long value = 0;
		try {
			value = std::stol(setting.substr(eq + 1));
		} catch (const std::exception &) {
			throw SourceError(path_ + ": v4l2.controls: " + setting + ": the value must be an integer");
		}
		v4l2_queryctrl query{};
		query.id = V4L2_CTRL_FLAG_NEXT_CTRL;
		bool found = false;
		std::string known;
		while (xioctl(fd_, VIDIOC_QUERYCTRL, &query) == 0) {
			if (!(query.flags & V4L2_CTRL_FLAG_DISABLED) && query.type != V4L2_CTRL_TYPE_CTRL_CLASS) {
				const std::string key = control_key(reinterpret_cast<const char *>(query.name));
				known += (known.empty() ? "" : ", ") + key;
				if (key == name) {
					found = true;
					break;
				}
			}
			query.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
		}
		if (!found)
			throw SourceError(path_ + ": v4l2.controls: no control '" + name + "' (the device has " +
					  known + ")");
		if (value < query.minimum || value > query.maximum)
			throw SourceError(path_ + ": v4l2.controls: " + name + " = " + std::to_string(value) +
					  " is outside " + std::to_string(query.minimum) + ".." +
					  std::to_string(query.maximum));
		v4l2_control control{};
		control.id = query.id;
		control.value = static_cast<int32_t>(value);
		if (xioctl(fd_, VIDIOC_S_CTRL, &control) != 0)
			throw SourceError(path_ + ": v4l2.controls: setting " + setting + ": " + errno_text());
	}
}

NextResult V4l2Device::next(int timeout_ms, V4l2Buffer &out)
{
	pollfd pfd{fd_, POLLIN, 0};
	const int ready = ::poll(&pfd, 1, timeout_ms);
	if (ready < 0)
		return errno == EINTR ? NextResult::Timeout : NextResult::Lost;
	if (ready == 0)
		return NextResult::Timeout;
	if (pfd.revents & (POLLERR | POLLHUP | POLLNVAL))
		return NextResult::Lost; // the device was unplugged (or stopped streaming)
	v4l2_buffer buffer{};
	buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
	buffer.memory = V4L2_MEMORY_MMAP;
	if (xioctl(fd_, VIDIOC_DQBUF, &buffer) != 0) {
		if (errno == EAGAIN)
			return NextResult::Timeout;
		spdlog::warn("v4l2: {}: VIDIOC_DQBUF: {}", path_, errno_text());
		return NextResult::Lost; // ENODEV, EIO: gone
	}
	const int64_t now = monotonic_ns();
	out.index = buffer.index;
	out.data = static_cast<const uint8_t *>(buffers_[buffer.index].start);
	out.size = buffer.bytesused;
	out.sequence = buffer.sequence;
	out.error = (buffer.flags & V4L2_BUF_FLAG_ERROR) != 0;
	const bool monotonic = (buffer.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
	if (!monotonic && monotonic_) {
		spdlog::warn("v4l2: {}: the driver gives no CLOCK_MONOTONIC buffer timestamps; using the dequeue time",
			     path_);
		monotonic_ = false;
	}
	out.timestamp_ns =
		monotonic ? int64_t{buffer.timestamp.tv_sec} * 1'000'000'000 + buffer.timestamp.tv_usec * 1000 : now;
	return NextResult::Frame;
}

bool V4l2Device::give_back(const V4l2Buffer &out)
{
	v4l2_buffer buffer{};
	buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
	buffer.memory = V4L2_MEMORY_MMAP;
	buffer.index = out.index;
	return xioctl(fd_, VIDIOC_QBUF, &buffer) == 0;
}

std::vector<DeviceDescription> list_devices()
{
	std::vector<DeviceDescription> out;
	std::error_code ec;
	std::vector<std::string> paths;
	for (const auto &entry : std::filesystem::directory_iterator("/dev", ec))
		if (entry.path().filename().string().rfind("video", 0) == 0)
			paths.push_back(entry.path().string());
	std::sort(paths.begin(), paths.end());
	for (const auto &path : paths) {
		DeviceDescription d;
		d.path = path;
		const int fd = ::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC);
		if (fd < 0) {
			d.error = errno_text();
			out.push_back(std::move(d));
			continue;
		}
		v4l2_capability cap{};
		if (xioctl(fd, VIDIOC_QUERYCAP, &cap) == 0) {
			d.card = reinterpret_cast<const char *>(cap.card);
			d.driver = reinterpret_cast<const char *>(cap.driver);
			d.bus = reinterpret_cast<const char *>(cap.bus_info);
			const uint32_t caps =
				(cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
			if (caps & V4L2_CAP_VIDEO_CAPTURE) {
				v4l2_fmtdesc desc{};
				desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
				for (desc.index = 0; xioctl(fd, VIDIOC_ENUM_FMT, &desc) == 0; ++desc.index)
					d.formats.push_back(fourcc_text(desc.pixelformat) +
							    sizes_text(fd, desc.pixelformat));
			} else {
				d.error = "not a capture node";
			}
		} else {
			d.error = "not a V4L2 device";
		}
		::close(fd);
		out.push_back(std::move(d));
	}
	return out;
}

} // namespace stereod::drivers::v4l2
