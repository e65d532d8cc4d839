// The Aravis capture source: one camera carrying both eyes, or two cameras paired by device timestamp.
//
// grab() runs on the pipeline's capture thread. With two cameras it keeps at most one popped buffer per
// camera; when both are held, their timestamps decide (see skew()): a pair within max_skew is copied into
// the pool frame, otherwise the older buffer has lost its partner and is given back, counted as unpaired.
// A camera that raises control-lost, or sends nothing for no_frame_timeout_s, makes grab() return Lost;
// reconnect() rebuilds the cameras that failed, and the pipeline keeps its clients meanwhile.
#include <array>
#include <cmath>
#include <memory>

#include <spdlog/spdlog.h>

#include "core/clock.hpp"
#include "drivers/aravis/aravis_camera.hpp"
#include "drivers/builtin.hpp"
#include "drivers/camera_frames.hpp"

#pragma GCC diagnostic ignored "-Wold-style-cast" // Aravis's pixel-format constants are C casts
#include <arv.h>

namespace stereod::drivers {
namespace {

using aravis::AravisCamera;
using aravis::BufferView;
using aravis::StreamStatistics;

constexpr size_t kLeft = 0, kRight = 1;
/// Frames of a camera reopened while its partner streams that are discarded (AravisCamera::start): stray
/// packets sit in the new socket before the camera's own, so they can only reach its first frame or two.
constexpr int kSettlingFrames = 2;

/// The camera's pixel format decides bytes per pixel and, for Bayer formats, the mosaic.
PixelRecipe recipe_for(const AravisConfig &config, uint32_t format, const std::string &format_name)
{
	PixelRecipe recipe;
	const auto layout = camera::parse_layout(config.layout);
	if (!layout)
		throw SourceError("aravis.layout = \"" + config.layout +
				  "\": must be pair, interleaved16, side_by_side or top_bottom");
	recipe.layout = *layout;
	const int bits = ARV_PIXEL_FORMAT_BIT_PER_PIXEL(format);
	recipe.rgb = format == ARV_PIXEL_FORMAT_RGB_8_PACKED;
	recipe.bytes_per_pixel = recipe.rgb ? 3 : bits / 8;
	if (bits != 8 && bits != 16 && !recipe.rgb)
		throw SourceError("aravis: pixel format " + format_name +
				  " is not supported (use Mono8, Mono16, Bayer*8, RGB8, or a 16-bit format with "
				  "layout interleaved16)");
	if (recipe.layout == camera::StereoLayout::Interleaved16 && recipe.bytes_per_pixel != 2)
		throw SourceError("aravis.layout = \"interleaved16\" needs a 16-bit pixel format (Mono16 / Raw16); the "
				  "camera sends " +
				  format_name);
	if ((recipe.layout == camera::StereoLayout::SideBySide || recipe.layout == camera::StereoLayout::TopBottom) &&
	    recipe.bytes_per_pixel != 1)
		throw SourceError("aravis.layout = \"" + config.layout +
				  "\" needs an 8-bit pixel format; the camera sends " + format_name);
	if (config.bayer == "auto") {
		switch (format) {
		case ARV_PIXEL_FORMAT_BAYER_RG_8:
			recipe.mosaic = camera::Mosaic::RGGB;
			break;
		case ARV_PIXEL_FORMAT_BAYER_GR_8:
			recipe.mosaic = camera::Mosaic::GRBG;
			break;
		case ARV_PIXEL_FORMAT_BAYER_GB_8:
			recipe.mosaic = camera::Mosaic::GBRG;
			break;
		case ARV_PIXEL_FORMAT_BAYER_BG_8:
			recipe.mosaic = camera::Mosaic::BGGR;
			break;
		default:
			break;
		}
	} else {
		recipe.mosaic = parse_mosaic(config.bayer, "aravis");
	}
	if (config.first_byte != "left" && config.first_byte != "right")
		throw SourceError("aravis.first_byte = \"" + config.first_byte + "\": must be left or right");
	recipe.first_is_left = config.first_byte == "left";
	recipe.output = choose_output(config.color, recipe.mosaic, recipe.rgb, "aravis");
	return recipe;
}

/// Per-camera state that outlives a reconnect: clock fit, frame ids, cumulative statistics.
struct CameraState {
	std::unique_ptr<AravisCamera> camera;
	camera::DeviceClock clock;
	camera::FrameIdCounter ids{16};
	BufferView pending;	  ///< popped and not yet paired
	int64_t pending_host = 0; ///< its timestamp on the host clock
	bool has_pending = false;
	int settling = 0;	   ///< first frames after a lone reopen still to discard (AravisCamera::start)
	int64_t last_frame_ns = 0; ///< host time of the last buffer of any kind
	camera::CadenceTracker cadence{0, 0};
	std::atomic<uint64_t> skipped_periods{0}, irregular{0}; ///< the cadence's counts, for status
	StreamStatistics before;				///< totals of the streams closed by reconnects
	uint64_t failed_before = 0;
	std::atomic<uint64_t> completed{0}, failures{0}, underruns{0}, resent{0}, missing_packets{0}, failed{0},
		missing_frames{0}, incomplete{0}, clock_restarts{0};
	std::atomic<int64_t> drift_ppb{0};
};

class AravisSource final : public FrameSource
{
public:
	explicit AravisSource(const SourceConfig &config) : config_(config.aravis)
	{
		if (config_.left.empty())
			throw SourceError("aravis.left: no camera given; " + aravis::found_cameras_text());
		paired_ = !config_.right.empty();
		if (paired_ && config_.layout != "pair")
			throw SourceError("aravis.right is set, so aravis.layout must be \"pair\" (got \"" +
					  config_.layout + "\")");
		if (!paired_ && config_.layout == "pair")
			throw SourceError(
				"aravis.layout = \"pair\" needs aravis.right; for one camera carrying both eyes "
				"choose interleaved16, side_by_side or top_bottom");
		// Default: a quarter period. Two frames further apart than that are not the same moment, and a frame
		// stamped late (a stalled camera) must not steal the partner of the next one, which is on time.
		const double rate = config_.frame_rate > 0 ? config_.frame_rate : 30.0;
		max_skew_ns_ =
			static_cast<int64_t>(config_.max_skew_ms > 0 ? config_.max_skew_ms * 1e6 : 0.25e9 / rate);
		if (config_.clock != "auto" && config_.clock != "shared" && config_.clock != "per_camera")
			throw SourceError("aravis.clock = \"" + config_.clock +
					  "\": must be auto, shared or per_camera");
		shared_clock_ = config_.clock == "shared" || (config_.clock == "auto" && config_.ptp);
		const int64_t period = config_.frame_rate > 0 && config_.trigger == "off"
					       ? static_cast<int64_t>(1e9 / config_.frame_rate)
					       : 0;
		for (auto &state : cams_)
			state.cadence = camera::CadenceTracker(period, max_skew_ns_);
		no_frame_ns_ = static_cast<int64_t>(config_.no_frame_timeout_s * 1e9);
		open(kLeft);
		if (paired_)
			open(kRight);
		// The cameras send from the first grab on (start_acquisition).
		const AravisCamera &left = *cams_[kLeft].camera;
		recipe_ = recipe_for(config_, left.pixel_format(), left.pixel_format_name());
		if (paired_) {
			const AravisCamera &right = *cams_[kRight].camera;
			if (right.width() != left.width() || right.height() != left.height() ||
			    right.pixel_format() != left.pixel_format())
				throw SourceError(
					"aravis: the two cameras differ: left " + std::to_string(left.width()) + "x" +
					std::to_string(left.height()) + " " + left.pixel_format_name() + ", right " +
					std::to_string(right.width()) + "x" + std::to_string(right.height()) + " " +
					right.pixel_format_name() + "; set aravis.width, height and pixel_format");
		}
		width_ = left.width();
		height_ = left.height();
		const cv::Size eye = camera::eye_size(recipe_.layout, width_, height_);
		scratch_.allocate(cv::Size(width_, height_));
		info_.name = "aravis";
		info_.description = paired_ ? left.description() + " + " + cams_[kRight].camera->description()
					    : left.description() + " (" + config_.layout + ")";
		info_.geometry = {eye.width, eye.height, recipe_.output, true, false, false, config_.frame_rate};
		info_.live = true;
		outage_.set_rate(config_.frame_rate);
		trigger_period_ns_ = config_.trigger == "software" && config_.frame_rate > 0
					     ? static_cast<int64_t>(1e9 / config_.frame_rate)
					     : 0;
	}

	~AravisSource() override
	{
		for (auto &state : cams_)
			release_pending(state);
	}

	const SourceInfo &info() const override { return info_; }

	GrabStatus grab(StereoFrame &into) override
	{
		start_acquisition();
		// Return within ~100 ms either way, so the pipeline sees a stop request promptly.
		const int64_t deadline = monotonic_ns() + 100'000'000;
		for (;;) {
			if (lost())
				return GrabStatus::Lost;
			fire_trigger();
			const int64_t now = monotonic_ns();
			if (now >= deadline)
				return GrabStatus::Timeout;
			const uint64_t wait_us =
				static_cast<uint64_t>(std::min<int64_t>(deadline - now, 20'000'000) / 1000);
			CameraState &left = cams_[kLeft];
			if (!left.has_pending && !take(left, wait_us))
				continue;
			if (!paired_)
				return emit(into, left, nullptr);
			CameraState &right = cams_[kRight];
			if (!right.has_pending && !take(right, wait_us))
				continue;
			switch (camera::pair_action(0, skew(left, right), max_skew_ns_)) {
			case camera::PairAction::Pair:
				return emit(into, left, &right);
			case camera::PairAction::DropLeft:
				spdlog::debug("aravis: left frame {} unpaired: right {} is {} ns later",
					      left.pending.frame_id, right.pending.frame_id, skew(left, right));
				release_pending(left);
				count_unpaired();
				break;
			case camera::PairAction::DropRight:
				spdlog::debug("aravis: right frame {} unpaired: left {} is {} ns later",
					      right.pending.frame_id, left.pending.frame_id, -skew(left, right));
				release_pending(right);
				count_unpaired();
				break;
			}
		}
	}

	bool reconnect() override
	{
		bool partner_streaming = false;
		std::array<bool, 2> to_start{};
		for (size_t side : {kLeft, kRight}) {
			if (side == kRight && !paired_)
				continue;
			CameraState &state = cams_[side];
			if (state.camera && !failed(state)) {
				release_pending(state); // its partner is gone: what it holds and queued is stale
				state.camera->drain();
				(state.camera->acquiring() ? partner_streaming : to_start[side]) = true;
				continue;
			}
			release_pending(state);
			retire(state);
			try {
				open(side);
				to_start[side] = true;
			} catch (const SourceError &e) {
				spdlog::debug("aravis: reconnect {}: {}", side == kLeft ? "left" : "right", e.what());
				return false;
			}
			const AravisCamera &fresh = *state.camera;
			if (fresh.width() != width_ || fresh.height() != height_ ||
			    fresh.pixel_format() != cams_[kLeft].camera->pixel_format()) {
				spdlog::warn("aravis: {} came back as {}x{} {}, not {}x{}; retrying",
					     fresh.description(), fresh.width(), fresh.height(),
					     fresh.pixel_format_name(), width_, height_);
				retire(state);
				return false;
			}
		}
		// Started only now, every stream existing (AravisCamera::start). A camera reopened while its partner
		// kept sending can still have taken a few of the partner's packets into its first frames: those
		// frames are discarded and counted (device.settling_discarded).
		for (size_t side : {kLeft, kRight}) {
			if (!to_start[side])
				continue;
			try {
				cams_[side].camera->start();
			} catch (const SourceError &e) {
				spdlog::debug("aravis: reconnect {}: {}", side == kLeft ? "left" : "right", e.what());
				return false;
			}
			cams_[side].settling = partner_streaming ? kSettlingFrames : 0;
		}
		// The frames the outage cost are counted at the first frame after it (OutageCounter): the cameras' own
		// counters restarted.
		outage_.reconnected();
		paired_once_ = false;
		const int64_t now = monotonic_ns();
		for (auto &state : cams_)
			state.last_frame_ns = now;
		return true;
	}

	SourceCounters counters() const override
	{
		SourceCounters out;
		out.drops["camera_failed"] = 0;
		out.drops["camera_missing_frames"] = 0;
		for (size_t side : {kLeft, kRight}) {
			if (side == kRight && !paired_)
				continue;
			const CameraState &s = cams_[side];
			const std::string prefix = side == kLeft ? "left_" : "right_";
			out.drops["camera_failed"] += s.failed.load();
			out.device[prefix + "completed"] = static_cast<int64_t>(s.completed.load());
			out.device[prefix + "failures"] = static_cast<int64_t>(s.failures.load());
			out.device[prefix + "underruns"] = static_cast<int64_t>(s.underruns.load());
			out.device[prefix + "resent_packets"] = static_cast<int64_t>(s.resent.load());
			out.device[prefix + "missing_packets"] = static_cast<int64_t>(s.missing_packets.load());
			out.device[prefix + "missing_frames"] = static_cast<int64_t>(s.missing_frames.load());
			out.device[prefix + "incomplete"] = static_cast<int64_t>(s.incomplete.load());
			out.device[prefix + "clock_restarts"] = static_cast<int64_t>(s.clock_restarts.load());
			out.device[prefix + "drift_ppb"] = s.drift_ppb.load();
			out.device[prefix + "skipped_periods"] = static_cast<int64_t>(s.skipped_periods.load());
			out.device[prefix + "irregular_intervals"] = static_cast<int64_t>(s.irregular.load());
		}
		// Frames lost on the wire by the right camera show up as unpaired left frames; the left camera's
		// own losses are the pipeline's source_gap (the frame sequence follows its ids).
		out.drops["unpaired"] = unpaired_.load();
		out.drops["outage"] = outage_.lost();
		out.device["startup_unpaired"] = static_cast<int64_t>(startup_unpaired_.load());
		out.device["settling_discarded"] = static_cast<int64_t>(settling_discarded_.load());
		out.device["skew_last_ns"] = skew_last_.load();
		out.device["skew_max_abs_ns"] = skew_max_abs_.load();
		return out;
	}

private:
	/// The cameras send from the first grab on, not from their opening: while the pipeline gets ready (its
	/// workers' warm-up) their frames would wait in the stream's buffers and reach the pipeline late. Every
	/// stream exists before any camera sends (AravisCamera::start says why). A reconnect starts the cameras
	/// it reopens itself.
	void start_acquisition()
	{
		if (acquisition_started_)
			return;
		for (size_t side : {kLeft, kRight})
			if (side == kLeft || paired_) {
				cams_[side].camera->start();
				cams_[side].last_frame_ns = monotonic_ns();
			}
		acquisition_started_ = true;
	}

	void open(size_t side)
	{
		CameraState &state = cams_[side];
		state.camera = std::make_unique<AravisCamera>(side == kLeft ? config_.left : config_.right, config_,
							      side == kLeft ? "left" : "right");
		state.clock.reset();
		state.ids.reset();
		state.cadence.reset();
		state.last_frame_ns = monotonic_ns();
	}

	/// Closes a camera, folding its stream's totals into the state's.
	void retire(CameraState &state)
	{
		if (!state.camera)
			return;
		const StreamStatistics s = state.camera->statistics();
		state.before.completed += s.completed;
		state.before.failures += s.failures;
		state.before.underruns += s.underruns;
		state.before.resent_packets += s.resent_packets;
		state.before.missing_packets += s.missing_packets;
		state.failed_before += state.camera->failed();
		state.camera.reset();
	}

	[[nodiscard]] bool failed(const CameraState &state) const
	{
		return !state.camera || state.camera->control_lost() ||
		       monotonic_ns() - state.last_frame_ns > no_frame_ns_;
	}

	[[nodiscard]] bool lost() const
	{
		if (failed(cams_[kLeft]) || (paired_ && failed(cams_[kRight]))) {
			for (size_t side : {kLeft, kRight})
				if ((side == kLeft || paired_) && failed(cams_[side]))
					spdlog::warn("aravis: {} camera {}: {}", side == kLeft ? "left" : "right",
						     side == kLeft ? config_.left : config_.right,
						     !cams_[side].camera ? "not open"
						     : cams_[side].camera->control_lost()
							     ? "control lost"
							     : "no frame within no_frame_timeout_s");
			return true;
		}
		return false;
	}

	void fire_trigger()
	{
		if (trigger_period_ns_ == 0)
			return;
		const int64_t now = monotonic_ns();
		if (now < next_trigger_ns_)
			return;
		for (auto &state : cams_)
			if (state.camera)
				state.camera->software_trigger();
		next_trigger_ns_ = std::max(next_trigger_ns_ + trigger_period_ns_, now);
	}

	/// Until the first pair after opening (or reconnecting), the cameras are still starting one after the
	/// other: frames of the first one have no partner yet. Those are counted apart, not as stream losses
	/// (an outage's own cost is counted at the first pair after it, OutageCounter).
	void count_unpaired() { (paired_once_ ? unpaired_ : startup_unpaired_).fetch_add(1); }

	/// Right minus left exposure time of the two pending frames. Cameras on one clock (PTP, or `clock =
	/// shared`) are compared on their own stamps: mapping each through the clock fit at a different moment
	/// would add the fit's own movement in between, which while the fit is young is up to the host's arrival
	/// jitter (on a loaded 2-core machine, enough to break pairs of frames exposed together). Otherwise each
	/// camera's stamps are mapped onto the host clock by its own fit, and those are compared.
	[[nodiscard]] int64_t skew(const CameraState &left, const CameraState &right) const
	{
		if (shared_clock_ && left.pending.device_ns != 0 && right.pending.device_ns != 0)
			return right.pending.device_ns - left.pending.device_ns;
		return right.pending_host - left.pending_host;
	}

	/// Pops the next buffer of one camera into its pending slot.
	bool take(CameraState &state, uint64_t timeout_us)
	{
		if (!state.camera->next(timeout_us, state.pending))
			return false;
		if (state.settling > 0) {
			--state.settling;
			settling_discarded_.fetch_add(1);
			state.camera->give_back(state.pending);
			return false;
		}
		BufferView &view = state.pending;
		state.last_frame_ns = view.arrival_ns;
		state.has_pending = true;
		state.missing_frames.fetch_add(state.ids.add(view.frame_id));
		if (!view.complete)
			state.incomplete.fetch_add(1);
		state.cadence.add(view.device_ns);
		state.skipped_periods.store(state.cadence.skipped_periods());
		state.irregular.store(state.cadence.irregular_intervals());
		// Device clock onto CLOCK_MONOTONIC; a device without a clock (timestamp 0) gets its arrival time.
		// Cameras on one clock (PTP) share one fit, so their skew is exactly that of their own stamps.
		if (view.device_ns != 0) {
			camera::DeviceClock &clock = shared_clock_ ? cams_[kLeft].clock : state.clock;
			if (!clock.add(view.device_ns, view.arrival_ns))
				state.clock_restarts.fetch_add(1);
			state.pending_host = clock.to_host(view.device_ns);
			state.drift_ppb.store(static_cast<int64_t>(std::llround(clock.drift() * 1e9)));
		} else {
			state.pending_host = view.arrival_ns;
		}
		publish_statistics(state);
		return true;
	}

	void publish_statistics(CameraState &state)
	{
		const StreamStatistics s = state.camera->statistics();
		state.completed.store(state.before.completed + s.completed);
		state.failures.store(state.before.failures + s.failures);
		state.underruns.store(state.before.underruns + s.underruns);
		state.resent.store(state.before.resent_packets + s.resent_packets);
		state.missing_packets.store(state.before.missing_packets + s.missing_packets);
		state.failed.store(state.failed_before + state.camera->failed());
	}

	void release_pending(CameraState &state)
	{
		if (state.has_pending && state.camera)
			state.camera->give_back(state.pending);
		state.has_pending = false;
		state.pending = {};
	}

	GrabStatus emit(StereoFrame &into, CameraState &left, CameraState *right)
	{
		into.reset_metadata();
		const BufferView &l = left.pending;
		try {
			if (l.width != width_ || l.height != height_)
				throw std::runtime_error("buffer is " + std::to_string(l.width) + "x" +
							 std::to_string(l.height) + ", the stream was opened at " +
							 std::to_string(width_) + "x" + std::to_string(height_));
			fill_eyes(recipe_, l.data, l.size, l.width, l.height, scratch_, into.left,
				  right ? nullptr : &into.right);
			if (right) {
				const BufferView &r = right->pending;
				fill_eyes(recipe_, r.data, r.size, r.width, r.height, scratch_, into.right, nullptr);
			}
			into.status = l.complete && (!right || right->pending.complete) ? FrameStatus::Ok
											: FrameStatus::Incomplete;
		} catch (const std::exception &e) {
			// A short or resized buffer: its pixels cannot be trusted, the frame still counts.
			spdlog::warn("aravis: frame {}: {}", l.frame_id, e.what());
			into.status = FrameStatus::Corrupt;
		}
		// The sequence follows the left camera's frame ids, so its lost frames are the pipeline's gaps.
		sequence_ += 1 + (left.missing_frames.load() - left_missing_seen_);
		left_missing_seen_ = left.missing_frames.load();
		into.sequence = sequence_;
		into.device_ns = left.pending_host;
		into.host_ns = right ? std::max(l.arrival_ns, right->pending.arrival_ns) : l.arrival_ns;
		// On arrival times: the exposure stamps go through a clock fit that restarts with a reopened camera.
		outage_.delivered(into.host_ns);
		into.lr_skew_ns = right ? skew(left, *right) : 0;
		paired_once_ = true;
		if (right) {
			skew_last_.store(into.lr_skew_ns);
			skew_max_abs_.store(std::max<int64_t>(skew_max_abs_.load(), std::llabs(into.lr_skew_ns)));
			release_pending(*right);
		}
		release_pending(left);
		return GrabStatus::Frame;
	}

	AravisConfig config_;
	bool paired_ = false;
	bool shared_clock_ = false; ///< both cameras' timestamps are on one clock (PTP): one fit for both
	int64_t max_skew_ns_ = 0;
	int64_t no_frame_ns_ = 0;
	int64_t trigger_period_ns_ = 0;
	int64_t next_trigger_ns_ = 0;
	int width_ = 0, height_ = 0;
	PixelRecipe recipe_;
	EyeScratch scratch_;
	SourceInfo info_;
	std::array<CameraState, 2> cams_;
	uint64_t sequence_ = 0;
	uint64_t left_missing_seen_ = 0;
	camera::OutageCounter outage_;
	bool paired_once_ = false;
	std::atomic<uint64_t> unpaired_{0}, startup_unpaired_{0}, settling_discarded_{0};
	bool acquisition_started_ = false; ///< the first grab started the cameras
	std::atomic<int64_t> skew_last_{0}, skew_max_abs_{0};
};

} // namespace

void register_aravis(SourceRegistry &registry)
{
	registry.add("aravis", "GigE Vision / USB3 Vision cameras through Aravis ([aravis])",
		     [](const SourceConfig &config) { return std::make_unique<AravisSource>(config); });
}

} // namespace stereod::drivers
