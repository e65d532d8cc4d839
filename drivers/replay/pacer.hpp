#pragma once
// Paces file-backed sources: at the recorded spacing of their timestamps, as fast as possible, or one
// frame per line on standard input.
#include <cstdint>
#include <cstdio>

#include "core/clock.hpp"
#include "drivers/source.hpp"

namespace stereod::drivers {

class Pacer
{
public:
	explicit Pacer(ReplayRate rate) : rate_(rate) {}

	/// Waits until the frame stamped `device_ns` is due. False when stepping and standard input closed.
	bool wait_for(int64_t device_ns)
	{
		switch (rate_) {
		case ReplayRate::Fast:
			return true;
		case ReplayRate::Step: {
			int c = 0;
			while ((c = std::getchar()) != EOF && c != '\n') {
			}
			return c != EOF;
		}
		case ReplayRate::Recorded:
			break;
		}
		const int64_t now = monotonic_ns();
		if (!started_) {
			started_ = true;
			host_start_ns_ = now;
			device_start_ns_ = device_ns;
			return true;
		}
		const int64_t due = host_start_ns_ + (device_ns - device_start_ns_);
		if (due > now)
			sleep_until_monotonic_ns(due);
		return true;
	}

private:
	ReplayRate rate_;
	bool started_ = false;
	int64_t host_start_ns_ = 0;
	int64_t device_start_ns_ = 0;
};

} // namespace stereod::drivers
