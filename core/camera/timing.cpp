#include "core/camera/timing.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereod::camera {

void DeviceClock::reset() noexcept
{
	next_ = 0;
	count_ = 0;
	bucket_next_ = 0;
	bucket_count_ = 0;
	current_valid_ = false;
	rate_ = 1.0;
	offset_ = 0;
}

bool DeviceClock::add(int64_t device_ns, int64_t host_ns, int64_t jump_ns)
{
	bool continues = true;
	if (count_ > 0) {
		const Sample &last = samples_[(next_ + kWindow - 1) % kWindow];
		const int64_t predicted = to_host(device_ns);
		// Small steps back are two cameras on one clock interleaving; a large one is a reset.
		if (device_ns + jump_ns < last.device_ns || std::llabs(host_ns - predicted) > jump_ns) {
			reset();
			++restarts_;
			continues = false;
		}
	}
	if (count_ == 0) {
		origin_device_ = device_ns;
		origin_host_ = host_ns;
	}
	const Sample sample{device_ns, host_ns};
	samples_[next_] = sample;
	next_ = (next_ + 1) % kWindow;
	count_ = std::min(count_ + 1, kWindow);
	add_to_bucket(sample);
	refit();
	return continues;
}

void DeviceClock::add_to_bucket(const Sample &sample) noexcept
{
	// host - device is the delivery delay plus the clocks' offset; its minimum per second is the envelope.
	auto delay = [](const Sample &s) { return s.host_ns - s.device_ns; };
	if (current_valid_ && sample.device_ns - current_start_ >= kBucketNs) {
		buckets_[bucket_next_] = current_;
		bucket_next_ = (bucket_next_ + 1) % kBuckets;
		bucket_count_ = std::min(bucket_count_ + 1, kBuckets);
		current_valid_ = false;
	}
	if (!current_valid_) {
		current_ = sample;
		current_start_ = sample.device_ns;
		current_valid_ = true;
	} else if (delay(sample) < delay(current_)) {
		current_ = sample;
	}
}

void DeviceClock::refit() noexcept
{
	// Keep the origin at the oldest sample of the offset window: differences stay small and exact.
	const Sample &oldest = samples_[(next_ + kWindow - count_) % kWindow];
	origin_device_ = oldest.device_ns;
	origin_host_ = oldest.host_ns;
	if (bucket_count_ >= kMinBuckets) {
		double mean_d = 0, mean_h = 0;
		for (size_t i = 0; i < bucket_count_; ++i) {
			mean_d += static_cast<double>(buckets_[i].device_ns - origin_device_);
			mean_h += static_cast<double>(buckets_[i].host_ns - origin_host_);
		}
		const double n = static_cast<double>(bucket_count_);
		mean_d /= n;
		mean_h /= n;
		double sdd = 0, sdh = 0;
		for (size_t i = 0; i < bucket_count_; ++i) {
			const double d = static_cast<double>(buckets_[i].device_ns - origin_device_) - mean_d;
			const double h = static_cast<double>(buckets_[i].host_ns - origin_host_) - mean_h;
			sdd += d * d;
			sdh += d * h;
		}
		if (sdd > 0)
			rate_ = sdh / sdd;
	}
	// Offset: the fastest delivery of the recent window and of every remembered second. Minutes of minima
	// give a floor that stays put; a window of seconds alone lets the floor jump whenever its fastest
	// sample slides out, and two cameras' floors would then jump apart.
	double lowest = std::numeric_limits<double>::infinity();
	for (size_t i = 0; i < count_; ++i)
		lowest = std::min(lowest, residual(samples_[i]));
	if (bucket_count_ >= kMinBuckets)
		for (size_t i = 0; i < bucket_count_; ++i)
			lowest = std::min(lowest, residual(buckets_[i]));
	offset_ = lowest;
}

int64_t DeviceClock::to_host(int64_t device_ns) const noexcept
{
	return origin_host_ +
	       static_cast<int64_t>(std::llround(offset_ + rate_ * static_cast<double>(device_ns - origin_device_)));
}

void OutageCounter::delivered(int64_t t_ns) noexcept
{
	if (open_ && fps_ > 0 && t_ns > last_ns_) {
		const auto periods = std::llround(static_cast<double>(t_ns - last_ns_) * 1e-9 * fps_);
		if (periods > 1)
			lost_.fetch_add(static_cast<uint64_t>(periods - 1), std::memory_order_relaxed);
	}
	open_ = false;
	have_last_ = true;
	last_ns_ = t_ns;
}

uint64_t FrameIdCounter::add(uint64_t id) noexcept
{
	uint64_t gap = 0;
	if (!started_) {
		started_ = true;
		if (unwrapped_ > 0)
			++unwrapped_; // a restart after reset(): the count goes on
	} else if (bits_ >= 64) {
		const uint64_t step = id - last_;
		if (step == 0 || step >= (uint64_t{1} << 62))
			return 0; // repeated or older
		gap = step - 1;
		unwrapped_ += gap + 1;
	} else {
		const uint64_t modulus = uint64_t{1} << bits_;
		if (zero_skipped_ && id == 0)
			return 0; // not a block id (16-bit GVSP never uses 0): nothing to count
		uint64_t step = (id + modulus - last_) % modulus;
		if (step == 0 || step > modulus / 2)
			return 0; // the same id again, or an older one arriving late: not a gap, and not newer
		if (zero_skipped_ && id < last_)
			--step; // the wrap skipped id 0
		gap = step - 1;
		unwrapped_ += gap + 1;
	}
	last_ = id;
	missing_ += gap;
	return gap;
}

} // namespace stereod::camera

namespace stereod::camera {

void CadenceTracker::add(int64_t device_ns) noexcept
{
	if (period_ <= 0 || device_ns == 0)
		return;
	if (last_ == 0 || device_ns <= last_) {
		last_ = device_ns;
		return;
	}
	// Compared with the previous frame, not with a grid: a grid anchored on a late frame would call every
	// later frame late.
	const double periods = static_cast<double>(device_ns - last_) / static_cast<double>(period_);
	const double slots = std::round(periods);
	if (slots > 1)
		skipped_ += static_cast<uint64_t>(slots) - 1;
	if (std::abs(periods - slots) * static_cast<double>(period_) > static_cast<double>(tolerance_) || slots < 1)
		++irregular_;
	last_ = device_ns;
}

} // namespace stereod::camera
