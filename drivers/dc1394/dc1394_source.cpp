// FireWire Point Grey Bumblebee2 / XB3 through libdc1394: a thin layer by design (there is no FireWire
// emulator to test against). The camera sends both eyes pixel-interleaved in Format_7 Mode 3 as Mono16 /
// Raw16; everything after the dequeue -- de-interleaving, demosaicing, the cycle-time clock, the frame
// counter -- is the same tested code the Aravis driver uses.
#include <cmath>
#include <memory>
#include <poll.h>
#include <sstream>

#include <dc1394/dc1394.h>
#include <spdlog/spdlog.h>

#include "core/clock.hpp"
#include "drivers/builtin.hpp"
#include "drivers/camera_frames.hpp"

namespace stereod::drivers {
namespace {

// Point Grey registers (offsets from the camera's command registers).
constexpr uint64_t kBayerTileMapping = 0x1040; ///< four ASCII letters: "RGGB", ..., "YYYY" for monochrome
constexpr uint64_t kFrameInfo = 0x12F8;	       ///< bit 0: embed the cycle-time stamp in the first 4 bytes
constexpr uint32_t kFrameInfoTimestamp = 0x1;

std::string guid_text(uint64_t guid)
{
	std::ostringstream out;
	out << std::hex << guid;
	return out.str();
}

struct Dc1394Deleter {
	void operator()(dc1394_t *d) const { dc1394_free(d); }
	void operator()(dc1394camera_t *c) const { dc1394_camera_free(c); }
	void operator()(dc1394camera_list_t *l) const { dc1394_camera_free_list(l); }
};

class Dc1394Source final : public FrameSource
{
public:
	explicit Dc1394Source(const SourceConfig &config) : config_(config.dc1394)
	{
		// libdc1394 prints its own errors to stderr; ours say the same with context.
		context_.reset(dc1394_new());
		if (!context_)
			throw SourceError(
				"dc1394: cannot start libdc1394 (no FireWire stack: is firewire-ohci loaded and "
				"/dev/fw* readable?)");
		open_camera();
		int64_t eye_w = 0, eye_h = 0;
		{
			uint32_t w = 0, h = 0;
			dc1394_get_image_size_from_video_mode(camera_.get(), DC1394_VIDEO_MODE_FORMAT7_3, &w, &h);
			eye_w = w;
			eye_h = h;
		}
		width_ = static_cast<int>(eye_w);
		height_ = static_cast<int>(eye_h);
		scratch_.allocate(cv::Size(width_, height_));
		info_.name = "dc1394";
		info_.description = description_;
		info_.geometry = {width_, height_, recipe_.output, true, false, false, config_.frame_rate};
		info_.live = true;
		outage_.set_rate(config_.frame_rate);
	}

	~Dc1394Source() override { close_camera(); }

	const SourceInfo &info() const override { return info_; }

	GrabStatus grab(StereoFrame &into) override
	{
		start_transmission();
		pollfd pfd{dc1394_capture_get_fileno(camera_.get()), POLLIN, 0};
		const int ready = ::poll(&pfd, 1, 100);
		if (ready == 0)
			return monotonic_ns() - last_frame_ns_ > 3'000'000'000 ? GrabStatus::Lost : GrabStatus::Timeout;
		if (ready < 0 || (pfd.revents & (POLLERR | POLLHUP | POLLNVAL)))
			return GrabStatus::Lost;
		dc1394video_frame_t *frame = nullptr;
		if (dc1394_capture_dequeue(camera_.get(), DC1394_CAPTURE_POLICY_POLL, &frame) != DC1394_SUCCESS)
			return GrabStatus::Lost;
		if (!frame)
			return GrabStatus::Timeout;
		last_frame_ns_ = monotonic_ns();
		into.reset_metadata();
		// libdc1394's own timestamp is the host's real-time clock at DMA completion, in microseconds;
		// carry it onto CLOCK_MONOTONIC by its age.
		const int64_t arrival =
			last_frame_ns_ - (realtime_ns() - static_cast<int64_t>(frame->timestamp) * 1000);
		int64_t device = 0;
		if (embedded_stamp_) {
			const uint8_t *b = frame->image;
			const uint32_t stamp = uint32_t{b[0]} << 24 | uint32_t{b[1]} << 16 | uint32_t{b[2]} << 8 | b[3];
			device = cycle_clock_.unwrap(stamp);
			if (!clock_.add(device, arrival))
				clock_restarts_.fetch_add(1);
		}
		try {
			fill_eyes(recipe_, frame->image, frame->image_bytes, static_cast<int>(frame->size[0]),
				  static_cast<int>(frame->size[1]), scratch_, into.left, &into.right);
			into.status = FrameStatus::Ok;
		} catch (const std::exception &e) {
			spdlog::warn("dc1394: frame {}: {}", frame->id, e.what());
			into.status = FrameStatus::Corrupt;
		}
		behind_max_.store(std::max<uint64_t>(behind_max_.load(), frame->frames_behind));
		into.sequence = ++sequence_;
		into.device_ns = embedded_stamp_ ? clock_.to_host(device) : arrival;
		into.host_ns = arrival;
		outage_.delivered(arrival);
		into.lr_skew_ns = 0; // one sensor board, one exposure trigger
		dc1394_capture_enqueue(camera_.get(), frame);
		return GrabStatus::Frame;
	}

	bool reconnect() override
	{
		close_camera();
		try {
			open_camera();
		} catch (const SourceError &e) {
			spdlog::debug("dc1394: reconnect: {}", e.what());
			return false;
		}
		outage_.reconnected(); // counted at the first frame after it (OutageCounter)
		return true;
	}

	SourceCounters counters() const override
	{
		SourceCounters out;
		out.drops["outage"] = outage_.lost();
		out.device["frames_behind_max"] = static_cast<int64_t>(behind_max_.load());
		out.device["clock_restarts"] = static_cast<int64_t>(clock_restarts_.load());
		return out;
	}

private:
	void open_camera()
	{
		dc1394camera_list_t *raw_list = nullptr;
		if (dc1394_camera_enumerate(context_.get(), &raw_list) != DC1394_SUCCESS)
			throw SourceError("dc1394: cannot enumerate FireWire cameras");
		std::unique_ptr<dc1394camera_list_t, Dc1394Deleter> list(raw_list);
		std::string found;
		uint64_t chosen = 0;
		for (uint32_t i = 0; i < list->num; ++i) {
			const uint64_t guid = list->ids[i].guid;
			found += (found.empty() ? "" : ", ") + guid_text(guid);
			if (!chosen && (config_.guid.empty() || config_.guid == guid_text(guid)))
				chosen = guid;
		}
		if (!chosen)
			throw SourceError("dc1394: " +
					  (config_.guid.empty() ? std::string("no FireWire camera found")
								: "no camera with dc1394.guid = " + config_.guid) +
					  (found.empty() ? " (the bus is empty or /dev/fw* is not accessible)"
							 : "; found: " + found));
		camera_.reset(dc1394_camera_new(context_.get(), chosen));
		if (!camera_)
			throw SourceError("dc1394: camera " + guid_text(chosen) + " found but cannot be opened");
		description_ =
			std::string(camera_->vendor) + " " + camera_->model + " (guid " + guid_text(chosen) + ")";
		uint32_t tile = 0;
		check(dc1394_get_control_register(camera_.get(), kBayerTileMapping, &tile),
		      "reading BAYER_TILE_MAPPING");
		const std::string tile_text{static_cast<char>(tile >> 24), static_cast<char>(tile >> 16),
					    static_cast<char>(tile >> 8), static_cast<char>(tile)};
		recipe_.layout = camera::StereoLayout::Interleaved16;
		recipe_.bytes_per_pixel = 2;
		recipe_.first_is_left = config_.first_byte == "left";
		recipe_.mosaic = config_.bayer == "auto"
					 ? (tile_text == "YYYY" ? camera::Mosaic::None
								: parse_mosaic(tile_text, "dc1394 (camera register)"))
					 : parse_mosaic(config_.bayer, "dc1394");
		recipe_.output = choose_output(config_.color, recipe_.mosaic, false, "dc1394");
		check(dc1394_video_set_iso_speed(camera_.get(), DC1394_ISO_SPEED_400), "setting ISO speed 400");
		check(dc1394_video_set_mode(camera_.get(), DC1394_VIDEO_MODE_FORMAT7_3), "selecting Format_7 Mode 3");
		const dc1394color_coding_t coding =
			recipe_.mosaic == camera::Mosaic::None ? DC1394_COLOR_CODING_MONO16 : DC1394_COLOR_CODING_RAW16;
		check(dc1394_format7_set_roi(camera_.get(), DC1394_VIDEO_MODE_FORMAT7_3, coding, DC1394_USE_MAX_AVAIL,
					     0, 0, DC1394_QUERY_FROM_CAMERA, DC1394_QUERY_FROM_CAMERA),
		      "setting the Format_7 ROI");
		if (config_.model == "xb3") {
			// The XB3 carries three sensors; its PAN control picks the pair sent in Mode 3
			// (Point Grey: 0 = right + middle, the narrow baseline; 1 = right + left, the wide one).
			check(dc1394_feature_set_value(camera_.get(), DC1394_FEATURE_PAN,
						       config_.sensors == "wide" ? 1 : 0),
			      "selecting the XB3 sensor pair (PAN)");
		}
		uint32_t info = 0;
		embedded_stamp_ = dc1394_get_control_register(camera_.get(), kFrameInfo, &info) == DC1394_SUCCESS &&
				  dc1394_set_control_register(camera_.get(), kFrameInfo, info | kFrameInfoTimestamp) ==
					  DC1394_SUCCESS;
		if (!embedded_stamp_)
			spdlog::warn(
				"dc1394: {}: no embedded cycle-time stamps; timestamps are the host's arrival time",
				description_);
		check(dc1394_capture_setup(camera_.get(), 8, DC1394_CAPTURE_FLAGS_DEFAULT), "setting up DMA capture");
		transmitting_ = false; // from the next grab on (start_transmission)
		clock_.reset();
		last_frame_ns_ = monotonic_ns();
		spdlog::info("dc1394: {}: Format_7 Mode 3, {} pixels interleaved, sensor tiles {}", description_,
			     coding == DC1394_COLOR_CODING_MONO16 ? "Mono16" : "Raw16", tile_text);
	}

	/// The camera sends from the first grab after its opening on: its 8 DMA buffers would otherwise fill, and
	/// frames be lost, while the pipeline gets ready (its workers' warm-up).
	void start_transmission()
	{
		if (transmitting_)
			return;
		check(dc1394_video_set_transmission(camera_.get(), DC1394_ON), "starting transmission");
		transmitting_ = true;
		last_frame_ns_ = monotonic_ns();
	}

	/// Throws naming the camera and the step when libdc1394 refuses it.
	void check(dc1394error_t err, const char *what) const
	{
		if (err != DC1394_SUCCESS)
			throw SourceError("dc1394: " + description_ + ": " + what + ": " +
					  dc1394_error_get_string(err));
	}

	void close_camera() noexcept
	{
		if (!camera_)
			return;
		dc1394_video_set_transmission(camera_.get(), DC1394_OFF);
		dc1394_capture_stop(camera_.get());
		camera_.reset();
	}

	Dc1394Config config_;
	std::unique_ptr<dc1394_t, Dc1394Deleter> context_;
	std::unique_ptr<dc1394camera_t, Dc1394Deleter> camera_;
	std::string description_;
	PixelRecipe recipe_;
	EyeScratch scratch_;
	SourceInfo info_;
	int width_ = 0, height_ = 0;
	bool embedded_stamp_ = false;
	bool transmitting_ = false;
	camera::CycleTimeClock cycle_clock_;
	camera::DeviceClock clock_;
	int64_t last_frame_ns_ = 0;
	uint64_t sequence_ = 0;
	std::atomic<uint64_t> behind_max_{0}, clock_restarts_{0};
	camera::OutageCounter outage_;
};

} // namespace

void register_dc1394(SourceRegistry &registry)
{
	registry.add("dc1394", "FireWire Point Grey Bumblebee2 / XB3 through libdc1394 ([dc1394])",
		     [](const SourceConfig &config) { return std::make_unique<Dc1394Source>(config); });
}

} // namespace stereod::drivers
