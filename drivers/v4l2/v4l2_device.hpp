#pragma once
// One Video4Linux2 capture device, owned: opening sets the format, frame rate and controls and maps and queues
// the driver's buffers; start() streams; destruction stops and unmaps. Buffers are dequeued and queued back
// forever; nothing is allocated per frame.
#include <cstdint>
#include <string>
#include <vector>

#include "drivers/source.hpp"

namespace stereod::drivers::v4l2 {

/// One dequeued buffer, valid until give_back().
struct V4l2Buffer {
	uint32_t index = 0;
	const uint8_t *data = nullptr;
	size_t size = 0;	  ///< bytes used
	uint32_t sequence = 0;	  ///< the driver's frame counter
	int64_t timestamp_ns = 0; ///< the driver's timestamp on CLOCK_MONOTONIC (or the dequeue time, see below)
	bool error = false;	  ///< the driver flagged the buffer (V4L2_BUF_FLAG_ERROR): data may be damaged
};

enum class NextResult : uint8_t { Frame, Timeout, Lost };

class V4l2Device
{
public:
	/// Opens and configures `path` and queues its buffers; throws SourceError naming the device, the setting
	/// and what the driver allows. It does not stream yet (start()).
	V4l2Device(const std::string &path, const V4l2Config &config);
	~V4l2Device();
	V4l2Device(const V4l2Device &) = delete;
	V4l2Device &operator=(const V4l2Device &) = delete;

	/// Starts streaming (VIDIOC_STREAMON) unless it already does; throws SourceError.
	void start();
	[[nodiscard]] bool streaming() const noexcept { return streaming_; }

	NextResult next(int timeout_ms, V4l2Buffer &buffer);
	/// Queues the buffer back; false when the device is gone.
	bool give_back(const V4l2Buffer &buffer);

	[[nodiscard]] int width() const noexcept { return width_; }
	[[nodiscard]] int height() const noexcept { return height_; }
	[[nodiscard]] uint32_t fourcc() const noexcept { return fourcc_; }
	[[nodiscard]] size_t bytes_per_line() const noexcept { return bytes_per_line_; }
	[[nodiscard]] double fps() const noexcept { return fps_; }
	[[nodiscard]] bool monotonic_timestamps() const noexcept { return monotonic_; }
	[[nodiscard]] const std::string &description() const noexcept { return description_; }

private:
	void configure(const V4l2Config &config);
	void set_controls(const std::vector<std::string> &controls);
	void close() noexcept;

	std::string path_;
	int fd_ = -1;
	struct Mapping {
		void *start = nullptr;
		size_t length = 0;
	};
	std::vector<Mapping> buffers_;
	bool streaming_ = false;
	int width_ = 0, height_ = 0;
	uint32_t fourcc_ = 0;
	size_t bytes_per_line_ = 0;
	double fps_ = 0;
	bool monotonic_ = true;
	std::string description_;
};

std::string fourcc_text(uint32_t fourcc);
/// "YUYV" -> its fourcc; throws SourceError for a name that is not four characters.
uint32_t fourcc_from(const std::string &name);
/// A control's name as v4l2-ctl prints it ("Exposure, Auto" -> "exposure_auto").
std::string control_key(const char *name);

/// Every V4L2 capture device under /dev, with its formats, sizes and frame rates: for `stereoctl devices`.
struct DeviceDescription {
	std::string path, card, driver, bus;
	std::vector<std::string> formats; ///< "YUYV 640x480@30 1280x720@10 ..."
	std::string error;
};
std::vector<DeviceDescription> list_devices();

} // namespace stereod::drivers::v4l2
