#include "core/latency.hpp"

#include <algorithm>
#include <cmath>

namespace stereod {

protocol::LatencySummary summarize_ns(std::vector<int64_t> samples)
{
	protocol::LatencySummary summary;
	summary.samples = samples.size();
	if (samples.empty())
		return summary;
	std::sort(samples.begin(), samples.end());
	auto at = [&](double q) {
		const auto rank = static_cast<size_t>(std::ceil(q * static_cast<double>(samples.size())));
		return static_cast<double>(samples[std::clamp<size_t>(rank, 1, samples.size()) - 1]) * 1e-6;
	};
	summary.p50_ms = at(0.50);
	summary.p90_ms = at(0.90);
	summary.p99_ms = at(0.99);
	summary.max_ms = static_cast<double>(samples.back()) * 1e-6;
	return summary;
}

protocol::LatencySummary LatencyWindow::summary() const
{
	const size_t count = std::min(next_, samples_ns_.size());
	return summarize_ns(
		std::vector<int64_t>(samples_ns_.begin(), samples_ns_.begin() + static_cast<std::ptrdiff_t>(count)));
}

} // namespace stereod
