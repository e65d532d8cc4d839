// The V4L2 capture source: one device carrying both eyes (side by side or top and bottom, the usual UVC
// stereo camera) or two devices paired by their buffer timestamps.
//
// Each buffer is turned into one image of the frame's pixel format (GREY used in place, YUYV's luma taken or
// converted to colour, MJPG decoded by libjpeg-turbo into a buffer allocated once), then split into the eyes.
// Timestamps are the driver's, on CLOCK_MONOTONIC when it says so (checked per buffer); sequence numbers
// count the frames the driver dropped.
#include <array>
#include <cmath>
#include <linux/videodev2.h>
#include <memory>

#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>
#include <turbojpeg.h>

#include "core/clock.hpp"
#include "drivers/builtin.hpp"
#include "drivers/camera_frames.hpp"
#include "drivers/v4l2/v4l2_device.hpp"

namespace stereod::drivers {
namespace {

using v4l2::NextResult;
using v4l2::V4l2Buffer;
using v4l2::V4l2Device;

constexpr size_t kLeft = 0, kRight = 1;

/// Decodes JPEG into a caller's buffer; the handle is made once.
class JpegDecoder
{
public:
	JpegDecoder() : handle_(tjInitDecompress()) {}
	~JpegDecoder()
	{
		if (handle_)
			tjDestroy(handle_);
	}
	JpegDecoder(const JpegDecoder &) = delete;
	JpegDecoder &operator=(const JpegDecoder &) = delete;

	/// Decodes into `out` (preallocated CV_8UC1 or CV_8UC3 at the image's size). False on a damaged image.
	bool decode(const uint8_t *data, size_t size, cv::Mat &out)
	{
		int width = 0, height = 0, subsampling = 0, colourspace = 0;
		if (tjDecompressHeader3(handle_, data, static_cast<unsigned long>(size), &width, &height, &subsampling,
					&colourspace) != 0 ||
		    width != out.cols || height != out.rows)
			return false;
		const int pixel = out.channels() == 1 ? TJPF_GRAY : TJPF_BGR;
		// tjDecompress2 returns -1 for warnings too (a truncated image still decodes); accept those.
		return tjDecompress2(handle_, data, static_cast<unsigned long>(size), out.data, out.cols,
				     static_cast<int>(out.step), out.rows, pixel, TJFLAG_FASTDCT) == 0 ||
		       tjGetErrorCode(handle_) == TJERR_WARNING;
	}

private:
	tjhandle handle_;
};

struct DeviceState {
	std::unique_ptr<V4l2Device> device;
	V4l2Buffer pending;
	bool has_pending = false;
	camera::FrameIdCounter sequence{32, false};
	int64_t last_frame_ns = 0;
	std::atomic<uint64_t> missing_frames{0}, error_buffers{0};
};

class V4l2Source final : public FrameSource
{
public:
	explicit V4l2Source(const SourceConfig &config) : config_(config.v4l2)
	{
		const auto layout = camera::parse_layout(config_.layout);
		if (!layout || *layout == camera::StereoLayout::Interleaved16)
			throw SourceError("v4l2.layout = \"" + config_.layout +
					  "\": must be pair, side_by_side or top_bottom");
		layout_ = *layout;
		paired_ = !config_.right.empty();
		if (paired_ != (layout_ == camera::StereoLayout::Pair))
			throw SourceError(paired_ ? "v4l2.right is set, so v4l2.layout must be \"pair\""
						  : "v4l2.layout = \"pair\" needs v4l2.right (a second device)");
		output_ = choose_output(config_.color, camera::Mosaic::None, false, "v4l2");
		max_skew_ns_ = static_cast<int64_t>(config_.max_skew_ms * 1e6);
		no_frame_ns_ = static_cast<int64_t>(config_.no_frame_timeout_s * 1e9);
		open(kLeft);
		if (paired_)
			open(kRight);
		const V4l2Device &left = *devices_[kLeft].device;
		width_ = left.width();
		height_ = left.height();
		fourcc_ = left.fourcc();
		check_format(left);
		if (paired_) {
			const V4l2Device &right = *devices_[kRight].device;
			if (right.width() != width_ || right.height() != height_ || right.fourcc() != fourcc_)
				throw SourceError(
					"v4l2: the two devices differ: left " + std::to_string(width_) + "x" +
					std::to_string(height_) + " " + v4l2::fourcc_text(fourcc_) + ", right " +
					std::to_string(right.width()) + "x" + std::to_string(right.height()) + " " +
					v4l2::fourcc_text(right.fourcc()) + "; set v4l2.width, height, pixel_format");
		}
		whole_.create(height_, width_, cv_type(output_));
		const cv::Size eye = camera::eye_size(layout_, width_, height_);
		info_.name = "v4l2";
		info_.description = paired_ ? left.description() + " + " + devices_[kRight].device->description()
					    : left.description() + " (" + config_.layout + ")";
		info_.geometry = {eye.width, eye.height, output_, true, false, false, left.fps()};
		info_.live = true;
		outage_.set_rate(left.fps());
	}

	~V4l2Source() override
	{
		for (auto &state : devices_)
			release(state);
	}

	const SourceInfo &info() const override { return info_; }

	GrabStatus grab(StereoFrame &into) override
	{
		start_streaming();
		const int64_t deadline = monotonic_ns() + 100'000'000;
		for (;;) {
			for (size_t side : {kLeft, kRight})
				if ((side == kLeft || paired_) &&
				    monotonic_ns() - devices_[side].last_frame_ns > no_frame_ns_) {
					spdlog::warn("v4l2: {}: no frame for {} s",
						     side == kLeft ? config_.left : config_.right,
						     config_.no_frame_timeout_s);
					return GrabStatus::Lost;
				}
			const int64_t now = monotonic_ns();
			if (now >= deadline)
				return GrabStatus::Timeout;
			const int wait_ms = static_cast<int>((deadline - now) / 1'000'000) + 1;
			DeviceState &left = devices_[kLeft];
			if (!left.has_pending) {
				const NextResult r = take(left, wait_ms);
				if (r == NextResult::Lost)
					return GrabStatus::Lost;
				if (r == NextResult::Timeout)
					continue;
			}
			if (!paired_)
				return emit(into, left, nullptr);
			DeviceState &right = devices_[kRight];
			if (!right.has_pending) {
				const NextResult r = take(right, wait_ms);
				if (r == NextResult::Lost)
					return GrabStatus::Lost;
				if (r == NextResult::Timeout)
					continue;
			}
			switch (camera::pair_action(left.pending.timestamp_ns, right.pending.timestamp_ns,
						    max_skew_ns_)) {
			case camera::PairAction::Pair:
				return emit(into, left, &right);
			case camera::PairAction::DropLeft:
				release(left);
				unpaired_.fetch_add(1);
				break;
			case camera::PairAction::DropRight:
				release(right);
				unpaired_.fetch_add(1);
				break;
			}
		}
	}

	/// The devices stream from the first grab on (and a reopened one from the grab after), not from their
	/// opening: their few buffers would otherwise fill, and frames be lost, while the pipeline gets ready
	/// (its workers' warm-up).
	void start_streaming()
	{
		for (size_t side : {kLeft, kRight}) {
			DeviceState &state = devices_[side];
			if ((side == kLeft || paired_) && state.device && !state.device->streaming()) {
				state.device->start();
				state.last_frame_ns = monotonic_ns(); // a silence is timed from here, not the opening
			}
		}
	}

	bool reconnect() override
	{
		for (auto &state : devices_)
			release(state);
		// Both devices are reopened: after an unplug the other device's queue is stale anyway.
		std::array<std::unique_ptr<V4l2Device>, 2> fresh;
		try {
			for (size_t side : {kLeft, kRight})
				if (side == kLeft || paired_) {
					devices_[side].device.reset();
					fresh[side] = std::make_unique<V4l2Device>(
						side == kLeft ? config_.left : config_.right, config_);
				}
		} catch (const SourceError &e) {
			spdlog::debug("v4l2: reconnect: {}", e.what());
			return false;
		}
		for (size_t side : {kLeft, kRight}) {
			if (!fresh[side])
				continue;
			if (fresh[side]->width() != width_ || fresh[side]->height() != height_ ||
			    fresh[side]->fourcc() != fourcc_) {
				spdlog::warn("v4l2: {} came back with another format; retrying",
					     fresh[side]->description());
				return false;
			}
			devices_[side].device = std::move(fresh[side]);
			devices_[side].sequence.reset();
		}
		outage_.reconnected(); // counted at the first frame after it (OutageCounter)
		return true;
	}

	SourceCounters counters() const override
	{
		SourceCounters out;
		out.drops["unpaired"] = unpaired_.load();
		out.drops["outage"] = outage_.lost();
		out.drops["decode_failed"] = decode_failed_.load();
		for (size_t side : {kLeft, kRight}) {
			if (side == kRight && !paired_)
				continue;
			const std::string prefix = side == kLeft ? "left_" : "right_";
			out.device[prefix + "missing_frames"] =
				static_cast<int64_t>(devices_[side].missing_frames.load());
			out.device[prefix + "error_buffers"] =
				static_cast<int64_t>(devices_[side].error_buffers.load());
		}
		out.device["skew_last_ns"] = skew_last_.load();
		return out;
	}

private:
	void open(size_t side)
	{
		DeviceState &state = devices_[side];
		state.device = std::make_unique<V4l2Device>(side == kLeft ? config_.left : config_.right, config_);
	}

	void check_format(const V4l2Device &device) const
	{
		switch (device.fourcc()) {
		case V4L2_PIX_FMT_GREY:
		case V4L2_PIX_FMT_YUYV:
		case V4L2_PIX_FMT_MJPEG:
		case V4L2_PIX_FMT_JPEG:
		case V4L2_PIX_FMT_RGB24:
		case V4L2_PIX_FMT_BGR24:
			return;
		default:
			throw SourceError(device.description() + ": pixel format " +
					  v4l2::fourcc_text(device.fourcc()) +
					  " is not supported (GREY, YUYV, MJPG, RGB3, BGR3); set v4l2.pixel_format");
		}
	}

	NextResult take(DeviceState &state, int timeout_ms)
	{
		const NextResult r = state.device->next(timeout_ms, state.pending);
		if (r != NextResult::Frame)
			return r;
		state.has_pending = true;
		state.last_frame_ns = monotonic_ns();
		state.missing_frames.fetch_add(state.sequence.add(state.pending.sequence));
		if (state.pending.error)
			state.error_buffers.fetch_add(1);
		return r;
	}

	void release(DeviceState &state)
	{
		if (state.has_pending && state.device)
			state.device->give_back(state.pending);
		state.has_pending = false;
	}

	/// The buffer as one image of the output format: a view for GREY into Mono8, else converted into whole_.
	bool to_image(const V4l2Device &device, const V4l2Buffer &buffer, cv::Mat &image)
	{
		const size_t stride = device.bytes_per_line();
		auto *data = const_cast<uint8_t *>(buffer.data);
		const bool colour = output_ == PixelFormat::Bgr8;
		switch (fourcc_) {
		case V4L2_PIX_FMT_MJPEG:
		case V4L2_PIX_FMT_JPEG:
			image = whole_;
			return jpeg_.decode(buffer.data, buffer.size, whole_);
		case V4L2_PIX_FMT_GREY: {
			if (buffer.size < stride * static_cast<size_t>(height_))
				return false;
			const cv::Mat grey(height_, width_, CV_8UC1, data, stride);
			if (colour)
				cv::cvtColor(grey, whole_, cv::COLOR_GRAY2BGR);
			image = colour ? whole_ : grey;
			return true;
		}
		case V4L2_PIX_FMT_YUYV: {
			if (buffer.size < stride * static_cast<size_t>(height_))
				return false;
			const cv::Mat yuyv(height_, width_, CV_8UC2, data, stride);
			if (colour)
				cv::cvtColor(yuyv, whole_, cv::COLOR_YUV2BGR_YUYV);
			else
				cv::extractChannel(yuyv, whole_, 0); // luma
			image = whole_;
			return true;
		}
		default: { // RGB24 / BGR24
			if (buffer.size < stride * static_cast<size_t>(height_))
				return false;
			const cv::Mat rgb(height_, width_, CV_8UC3, data, stride);
			const bool is_rgb = fourcc_ == V4L2_PIX_FMT_RGB24;
			if (colour)
				is_rgb ? cv::cvtColor(rgb, whole_, cv::COLOR_RGB2BGR) : rgb.copyTo(whole_);
			else
				cv::cvtColor(rgb, whole_, is_rgb ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
			image = whole_;
			return true;
		}
		}
	}

	GrabStatus emit(StereoFrame &into, DeviceState &left, DeviceState *right)
	{
		into.reset_metadata();
		bool ok = true;
		cv::Mat image;
		if (!to_image(*left.device, left.pending, image)) {
			ok = false;
		} else if (!right) {
			const auto [l, r] = camera::split_views(image, layout_);
			l.copyTo(into.left);
			r.copyTo(into.right);
		} else {
			image.copyTo(into.left);
			cv::Mat right_image;
			if (to_image(*right->device, right->pending, right_image))
				right_image.copyTo(into.right);
			else
				ok = false;
		}
		if (!ok)
			decode_failed_.fetch_add(1);
		const bool damaged = left.pending.error || (right && right->pending.error);
		into.status = !ok ? FrameStatus::Corrupt : damaged ? FrameStatus::Incomplete : FrameStatus::Ok;
		sequence_ += 1 + (left.missing_frames.load() - left_missing_seen_);
		left_missing_seen_ = left.missing_frames.load();
		into.sequence = sequence_;
		into.device_ns = left.pending.timestamp_ns;
		into.host_ns = monotonic_ns();
		outage_.delivered(into.device_ns);
		into.lr_skew_ns = right ? right->pending.timestamp_ns - left.pending.timestamp_ns : 0;
		skew_last_.store(into.lr_skew_ns);
		if (right)
			release(*right);
		release(left);
		return GrabStatus::Frame;
	}

	V4l2Config config_;
	camera::StereoLayout layout_ = camera::StereoLayout::SideBySide;
	bool paired_ = false;
	PixelFormat output_ = PixelFormat::Mono8;
	int64_t max_skew_ns_ = 0, no_frame_ns_ = 0;
	int width_ = 0, height_ = 0;
	uint32_t fourcc_ = 0;
	cv::Mat whole_; ///< one converted camera image, allocated once
	JpegDecoder jpeg_;
	SourceInfo info_;
	std::array<DeviceState, 2> devices_;
	uint64_t sequence_ = 0, left_missing_seen_ = 0;
	camera::OutageCounter outage_;
	std::atomic<uint64_t> unpaired_{0}, decode_failed_{0};
	std::atomic<int64_t> skew_last_{0};
};

} // namespace

void register_v4l2(SourceRegistry &registry)
{
	registry.add("v4l2", "Video4Linux2 devices: UVC cameras, side-by-side stereo cameras ([v4l2])",
		     [](const SourceConfig &config) { return std::make_unique<V4l2Source>(config); });
}

} // namespace stereod::drivers
