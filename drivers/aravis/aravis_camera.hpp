#pragma once
// One GigE Vision / USB3 Vision camera and its stream, owned: opening configures it from AravisConfig,
// pushes every stream buffer once; start() starts acquisition; destruction stops and frees everything. The
// buffers are then recycled between the stream and the source forever (no allocation per frame).
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "drivers/source.hpp"

// Aravis is a GObject C library; keep its types out of the headers that include this one.
struct _ArvCamera;
struct _ArvStream;
struct _ArvBuffer;

namespace stereod::drivers::aravis {

/// What one buffer carries, read once when it is popped.
struct BufferView {
	_ArvBuffer *buffer = nullptr;
	const uint8_t *data = nullptr;
	size_t size = 0;
	int width = 0;
	int height = 0;
	uint32_t pixel_format = 0; ///< PFNC code
	uint64_t frame_id = 0;
	int64_t device_ns = 0;	///< the camera's timestamp; 0 when it has no clock
	int64_t arrival_ns = 0; ///< CLOCK_MONOTONIC when the buffer was complete on the host
	bool complete = true;	///< false: packets are missing, the rest of the image is valid
};

/// Cumulative stream statistics of one camera (kept across reconnects by the source).
struct StreamStatistics {
	uint64_t completed = 0;
	uint64_t failures = 0;
	uint64_t underruns = 0;
	uint64_t resent_packets = 0;
	uint64_t missing_packets = 0;
};

class AravisCamera
{
public:
	/// Opens and configures `id` and creates its stream, ready for start(). Throws SourceError naming the
	/// camera, the feature, the value and what the camera allows, or (camera not found) the cameras found.
	AravisCamera(const std::string &id, const AravisConfig &config, const std::string &role);
	~AravisCamera();
	AravisCamera(const AravisCamera &) = delete;
	AravisCamera &operator=(const AravisCamera &) = delete;

	/// The next buffer, waiting at most `timeout_us`. Buffers with an unusable status (aborted, wrong size,
	/// ...) are given back and counted in failed(); a buffer with missing packets is returned incomplete.
	/// Returns false on timeout. Every returned buffer must go back through give_back().
	bool next(uint64_t timeout_us, BufferView &view);
	void give_back(BufferView &view);

	/// Starts acquisition. Kept apart from the constructor so that a source opens every stream before any
	/// camera sends: with a packet socket (CAP_NET_RAW), Aravis attaches the socket's port filter only after
	/// creating it, and a stream created while another camera on the host already sends can take some of
	/// that camera's packets into its first frame (seen on two fake cameras: packets 6-9 of the left image
	/// inside a right frame marked complete).
	void start();

	void software_trigger();
	/// Gives back every buffer already waiting (frames that arrived while the other camera was away).
	void drain();
	/// Set from Aravis's heartbeat thread when the device stops answering.
	[[nodiscard]] bool control_lost() const noexcept { return control_lost_.load(); }
	[[nodiscard]] StreamStatistics statistics() const;
	[[nodiscard]] uint64_t failed() const noexcept { return failed_; }
	[[nodiscard]] bool acquiring() const noexcept { return acquiring_; }
	[[nodiscard]] int width() const noexcept { return width_; }
	[[nodiscard]] int height() const noexcept { return height_; }
	[[nodiscard]] uint32_t pixel_format() const noexcept { return pixel_format_; }
	[[nodiscard]] const std::string &pixel_format_name() const noexcept { return pixel_format_name_; }
	[[nodiscard]] const std::string &description() const noexcept { return description_; }
	[[nodiscard]] bool is_gige() const noexcept { return gige_; }

private:
	void configure(const AravisConfig &config);
	void close() noexcept;

	std::string id_;
	std::string role_;
	_ArvCamera *camera_ = nullptr;
	_ArvStream *stream_ = nullptr;
	unsigned long lost_handler_ = 0;
	std::atomic<bool> control_lost_{false};
	uint64_t failed_ = 0;
	int width_ = 0;
	int height_ = 0;
	uint32_t pixel_format_ = 0;
	size_t payload_ = 0; ///< bytes of every stream buffer
	int buffers_ = 0;
	std::string pixel_format_name_;
	std::string description_;
	bool gige_ = false;
	bool acquiring_ = false;
};

/// Every camera Aravis finds (GigE discovery on every interface, USB3 Vision on the bus), with what each
/// can do: for `stereoctl devices`. Opening a camera to read its features never starts a stream.
struct DeviceDescription {
	std::string id;
	std::string vendor, model, serial;
	std::string transport; ///< "GigE Vision", "USB3 Vision", ...
	std::string address;
	std::vector<std::string> pixel_formats;
	int max_width = 0, max_height = 0;
	double min_fps = 0, max_fps = 0;
	std::string error; ///< set when the camera was found but could not be opened
};
std::vector<DeviceDescription> list_devices();

/// "no camera" help text: the ids Aravis found, for error messages.
std::string found_cameras_text();

} // namespace stereod::drivers::aravis
