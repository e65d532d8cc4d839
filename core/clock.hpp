#pragma once
// Host time. Every timestamp the pipeline produces is CLOCK_MONOTONIC in int64 nanoseconds, so that
// latencies are differences of one clock that never jumps.
#include <cstdint>
#include <ctime>

namespace stereod {

inline int64_t monotonic_ns() noexcept
{
	timespec ts{};
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
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
