#pragma once
// Per-stage wall time, recorded into the result so every message says where its time went.
#include <string>
#include <vector>

#include "core/clock.hpp"
#include "core/result.hpp"

namespace stereod {

class StageTimer
{
public:
	StageTimer(std::vector<StageTime> &sink, std::string name)
		: sink_(sink), name_(std::move(name)), start_ns_(monotonic_ns())
	{
	}
	StageTimer(const StageTimer &) = delete;
	StageTimer &operator=(const StageTimer &) = delete;
	~StageTimer() { sink_.push_back({std::move(name_), static_cast<double>(monotonic_ns() - start_ns_) * 1e-6}); }

private:
	std::vector<StageTime> &sink_;
	std::string name_;
	int64_t start_ns_;
};

} // namespace stereod
