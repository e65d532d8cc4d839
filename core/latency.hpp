#pragma once
// A window of recent latencies and their percentiles, for the status message and the benchmarks.
#include <cstdint>
#include <vector>

#include "core/protocol.hpp"

namespace stereod {

class LatencyWindow
{
public:
	explicit LatencyWindow(size_t capacity) : samples_ns_(capacity) {}
	void add(int64_t latency_ns) noexcept
	{
		samples_ns_[next_ % samples_ns_.size()] = latency_ns;
		++next_;
	}
	[[nodiscard]] protocol::LatencySummary summary() const;

private:
	std::vector<int64_t> samples_ns_;
	size_t next_ = 0;
};

/// Percentiles (nearest rank) of the given samples in nanoseconds, reported in milliseconds.
protocol::LatencySummary summarize_ns(std::vector<int64_t> samples);

} // namespace stereod
