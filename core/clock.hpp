#pragma once
// Host time. Every timestamp the pipeline produces is CLOCK_MONOTONIC in int64 nanoseconds, so that
// latencies are differences of one clock that never jumps.
#include <cerrno>
#include <cstdint>
#include <ctime>

namespace stereod {

inline int64_t monotonic_ns() noexcept
{
	timespec ts{};
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

/// Sleeps until CLOCK_MONOTONIC reaches `when_ns` (at once if it has), through signals.
inline void sleep_until_monotonic_ns(int64_t when_ns) noexcept
{
	const timespec ts{static_cast<time_t>(when_ns / 1'000'000'000), static_cast<long>(when_ns % 1'000'000'000)};
	while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
	}
}

/// CLOCK_REALTIME in int64 nanoseconds: only for carrying a library's wall-clock stamp onto CLOCK_MONOTONIC by
/// its age (Aravis's system timestamps, libdc1394's frame timestamps).
inline int64_t realtime_ns() noexcept
{
	timespec ts{};
	clock_gettime(CLOCK_REALTIME, &ts);
	return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

} // namespace stereod
