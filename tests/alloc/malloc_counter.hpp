#pragma once
// Counts every heap allocation of the process: glibc's malloc family is interposed (C libraries, OpenCV's image
// buffers and, through them, C++'s operator new all end there). Link malloc_counter.cpp into a test binary of
// its own; never under a sanitizer, whose runtime interposes malloc itself.
#include <cstdint>
#include <ostream>

namespace stereod::test {

/// Counting on (from zero) or off, for every thread of the process.
void count_allocations(bool on);
/// Allocations counted while counting was on.
uint64_t allocations_counted();

/// Allocations made while `run` runs.
template <typename F>
uint64_t allocations_during(F &&run)
{
	count_allocations(true);
	run();
	count_allocations(false);
	return allocations_counted();
}

/// Allocations counted frame by frame: a per-frame allocation shows in every frame, a one-off (a library's
/// thread starting late) in one.
struct FrameAllocations {
	uint64_t total = 0;
	int frames = 0, frames_allocating = 0;
	int first_allocating = -1; ///< index of the first frame that allocated, -1 for none
	bool delivered = true;
	void add(uint64_t n)
	{
		if (n > 0 && first_allocating < 0)
			first_allocating = frames;
		total += n;
		++frames;
		frames_allocating += n > 0 ? 1 : 0;
	}
	/// The steady state: no frame allocates, but for one one-off.
	[[nodiscard]] bool steady() const { return frames_allocating <= 1; }
};

inline std::ostream &operator<<(std::ostream &out, const FrameAllocations &a)
{
	return out << a.total << " allocations in " << a.frames_allocating << " of " << a.frames << " frames";
}

} // namespace stereod::test
