#pragma once
// Counts every heap allocation of the process: glibc's malloc family is interposed (C libraries, OpenCV's image
// buffers and, through them, C++'s operator new all end there). Link malloc_counter.cpp into a test binary of
// its own; never under a sanitizer, whose runtime interposes malloc itself.
#include <cstdint>

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

} // namespace stereod::test
