#pragma once
// Camera timing, pure: a device clock mapped onto CLOCK_MONOTONIC, frame counters that wrap, and the pairing
// rule for two cameras. No I/O, no allocation after construction.
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

namespace stereod::camera {

/// Maps a camera's clock onto the host's CLOCK_MONOTONIC by an online fit of offset and drift.
///
/// Each frame gives one sample: the device's timestamp of the frame and the host time the frame arrived.
/// The arrival is later than the device time by the transfer delay, which is never negative, mostly near
/// its floor, with long tails (a busy host, a retransmission). So the fit follows the lower envelope -- the
/// fastest deliveries -- never the mean:
///  - drift (rate): the least-squares line through the fastest delivery of each second, over up to the last
///    kBuckets seconds. A per-second minimum is steady to microseconds where single samples jump by
///    milliseconds, and minutes of baseline make the slope exact to a few ppm. Until kMinBuckets seconds are
///    in, the rate is taken as 1 (drift under 100 ppm costs under 1 us per 10 ms of offset age);
///  - offset: the smallest residual among the last kWindow samples and (once the rate is fitted) the
///    per-second minima, so the floor does not jump when one fast sample leaves the window.
/// The mapped time is therefore "device time on the host clock, plus the minimum transfer delay". Two
/// cameras on the same link get the same floor, so their mapped times are directly comparable.
/// A device clock that jumps (camera reset, a clock restarting at zero) restarts the fit.
class DeviceClock
{
public:
	static constexpr size_t kWindow = 128;
	static constexpr size_t kBuckets = 240;
	static constexpr size_t kMinBuckets = 10;
	static constexpr int64_t kBucketNs = 1'000'000'000;

	/// Adds a sample; returns false (and restarts the fit from this sample) when it does not continue the
	/// previous ones (device time went back, or device and host disagree, by more than `jump_ns`). Samples
	/// of several cameras on one clock (PTP) may be mixed.
	bool add(int64_t device_ns, int64_t host_ns, int64_t jump_ns = 1'000'000'000);
	/// The host CLOCK_MONOTONIC time of `device_ns`. Needs at least one sample.
	[[nodiscard]] int64_t to_host(int64_t device_ns) const noexcept;
	/// Host time per device time, minus 1 (e.g. 50e-6 for a device clock 50 ppm slow).
	[[nodiscard]] double drift() const noexcept { return rate_ - 1.0; }
	[[nodiscard]] size_t samples() const noexcept { return count_; }
	[[nodiscard]] uint64_t restarts() const noexcept { return restarts_; }
	void reset() noexcept;

private:
	struct Sample {
		int64_t device_ns;
		int64_t host_ns;
	};
	void add_to_bucket(const Sample &sample) noexcept;
	void refit() noexcept;
	[[nodiscard]] double residual(const Sample &s) const noexcept
	{
		return static_cast<double>(s.host_ns - origin_host_) -
		       rate_ * static_cast<double>(s.device_ns - origin_device_);
	}

	std::array<Sample, kWindow> samples_{};
	size_t next_ = 0;			 ///< where the next sample goes
	size_t count_ = 0;			 ///< valid samples, at most kWindow
	std::array<Sample, kBuckets> buckets_{}; ///< the fastest delivery of each finished second
	size_t bucket_next_ = 0;
	size_t bucket_count_ = 0;
	Sample current_{};	    ///< the fastest delivery so far in the second being filled
	int64_t current_start_ = 0; ///< device time where that second began
	bool current_valid_ = false;
	// The fit: host = origin_host_ + offset_ + rate_ * (device - origin_device_), in doubles relative to an
	// origin near the data so that nanosecond epochs keep their precision.
	int64_t origin_device_ = 0;
	int64_t origin_host_ = 0;
	double rate_ = 1.0;
	double offset_ = 0;
	uint64_t restarts_ = 0;
};

/// Turns a camera's frame ids (16-bit GVSP block ids that wrap from 65535 to 1, skipping 0, or 64-bit ids)
/// into a counter that never wraps, and counts the ids that never arrived.
class FrameIdCounter
{
public:
	/// `bits`: 16 for GigE Vision 1.x block ids, 32 for V4L2 sequence numbers, 64 for 64-bit ids.
	/// `zero_skipped`: the wrap goes from the largest id to 1 (GVSP block ids never use 0).
	explicit FrameIdCounter(int bits = 16, bool zero_skipped = true) noexcept
		: bits_(bits), zero_skipped_(zero_skipped)
	{
	}
	/// Returns the frames missing between the previous id and this one (0 for the first id).
	uint64_t add(uint64_t id) noexcept;
	[[nodiscard]] uint64_t unwrapped() const noexcept { return unwrapped_; }
	[[nodiscard]] uint64_t missing() const noexcept { return missing_; }
	void reset() noexcept { started_ = false; }

private:
	int bits_;
	bool zero_skipped_;
	bool started_ = false;
	uint64_t last_ = 0;
	uint64_t unwrapped_ = 0;
	uint64_t missing_ = 0;
};

/// The frames a camera's outage cost: the periods of its nominal rate between the last frame delivered
/// before the camera was lost and the first one delivered after it came back, less one. Measured from
/// those two frames, not from when the loss was noticed (a silence timeout can come seconds later) nor from
/// when the reopening began or ended (the camera's start-up after it is lost time too). The camera's own
/// counters restart with it, so they cannot say. Written by the capture thread, read by any.
class OutageCounter
{
public:
	explicit OutageCounter(double nominal_fps = 0) noexcept : fps_(nominal_fps) {}
	void set_rate(double nominal_fps) noexcept { fps_ = nominal_fps; }
	/// A frame delivered, stamped `t_ns` (one clock for every frame); it ends an outage reconnected() began.
	void delivered(int64_t t_ns) noexcept;
	/// The camera was reopened: the next frame delivered ends the outage. Before any frame there is nothing
	/// to measure from, and nothing is counted.
	void reconnected() noexcept { open_ = have_last_; }
	/// Frames lost to outages so far.
	[[nodiscard]] uint64_t lost() const noexcept { return lost_.load(std::memory_order_relaxed); }

private:
	double fps_;
	int64_t last_ns_ = 0;
	bool have_last_ = false, open_ = false;
	std::atomic<uint64_t> lost_{0};
};

/// IEEE 1394 cycle time as FireWire cameras stamp their frames (Point Grey's embedded timestamp): 7 bits of
/// seconds (wrapping every 128 s), 13 bits of 125 us cycles, 12 bits of 1/3072 cycle offsets. Turns the
/// stamps into a device clock in nanoseconds that does not wrap, for DeviceClock.
class CycleTimeClock
{
public:
	static constexpr int64_t kWrapNs = 128'000'000'000;
	/// Nanoseconds within the 128 s cycle-time period.
	static constexpr int64_t decode(uint32_t stamp) noexcept
	{
		const int64_t seconds = stamp >> 25;
		const int64_t cycles = (stamp >> 12) & 0x1fff;
		const int64_t offset = stamp & 0xfff;
		return seconds * 1'000'000'000 + cycles * 125'000 + offset * 125'000 / 3072;
	}
	/// The stamp on a clock that keeps counting past each 128 s wrap.
	int64_t unwrap(uint32_t stamp) noexcept
	{
		const int64_t t = decode(stamp);
		if (started_ && t < last_)
			base_ += kWrapNs;
		started_ = true;
		last_ = t;
		return base_ + t;
	}

private:
	bool started_ = false;
	int64_t last_ = 0;
	int64_t base_ = 0;
};

/// Follows a free-running camera's frame cadence. Consecutive frames are a whole number of frame periods
/// apart; a camera that stalls (a busy sender, a bus hiccup) skips periods without a frame-id gap, or sends
/// a frame off its cadence. A partner camera's frames of those moments can have no pair, so both are
/// counted: every unpaired frame can then be traced to the camera that caused it.
class CadenceTracker
{
public:
	/// `period_ns`: the nominal frame period (0 = not free-running: nothing is tracked). `tolerance_ns`: how
	/// far from a whole number of periods an interval may be and still be regular.
	CadenceTracker(int64_t period_ns, int64_t tolerance_ns) noexcept : period_(period_ns), tolerance_(tolerance_ns)
	{
	}
	void add(int64_t device_ns) noexcept;
	void reset() noexcept { last_ = 0; }
	[[nodiscard]] uint64_t skipped_periods() const noexcept { return skipped_; }
	/// Intervals off a whole number of periods by more than the tolerance (a late frame makes up to two).
	[[nodiscard]] uint64_t irregular_intervals() const noexcept { return irregular_; }

private:
	int64_t period_;
	int64_t tolerance_;
	int64_t last_ = 0;
	uint64_t skipped_ = 0;
	uint64_t irregular_ = 0;
};

enum class PairAction : uint8_t {
	Pair,	   ///< the two frames belong together
	DropLeft,  ///< the left frame is older than any right frame it could pair with
	DropRight, ///< the right frame is older than any left frame it could pair with
};

/// Two cameras' oldest unpaired frames, by their host-mapped timestamps: pair them when they are at most
/// `max_skew_ns` apart, otherwise the older one has lost its partner (the partner was lost, or arrived
/// earlier and was dropped) and is discarded -- counted, never paired with the wrong frame.
constexpr PairAction pair_action(int64_t left_ns, int64_t right_ns, int64_t max_skew_ns) noexcept
{
	const int64_t skew = right_ns - left_ns;
	if (skew > max_skew_ns)
		return PairAction::DropLeft;
	if (-skew > max_skew_ns)
		return PairAction::DropRight;
	return PairAction::Pair;
}

} // namespace stereod::camera
