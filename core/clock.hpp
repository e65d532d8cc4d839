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

} // namespace stereod
