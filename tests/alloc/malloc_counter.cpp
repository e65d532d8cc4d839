#include "tests/alloc/malloc_counter.hpp"

#include <atomic>
#include <cerrno>
#include <cstddef>

// glibc's own allocator, under the names it exports for interposers like this one.
extern "C" {
void *__libc_malloc(size_t size);
void *__libc_calloc(size_t count, size_t size);
void *__libc_realloc(void *p, size_t size);
void *__libc_memalign(size_t alignment, size_t size);
}

namespace {

// Globals by necessity: malloc is one.
std::atomic<bool> g_counting{false};
std::atomic<uint64_t> g_allocations{0};

void count()
{
	if (g_counting.load(std::memory_order_relaxed))
		g_allocations.fetch_add(1, std::memory_order_relaxed);
}

} // namespace

namespace stereod::test {

void count_allocations(bool on)
{
	if (on)
		g_allocations.store(0);
	g_counting.store(on);
}

uint64_t allocations_counted()
{
	return g_allocations.load();
}

} // namespace stereod::test

extern "C" {
void *malloc(size_t size)
{
	count();
	return __libc_malloc(size);
}
void *calloc(size_t n, size_t size)
{
	count();
	return __libc_calloc(n, size);
}
void *realloc(void *p, size_t size)
{
	count();
	return __libc_realloc(p, size);
}
void *memalign(size_t alignment, size_t size)
{
	count();
	return __libc_memalign(alignment, size);
}
void *aligned_alloc(size_t alignment, size_t size)
{
	count();
	return __libc_memalign(alignment, size);
}
int posix_memalign(void **out, size_t alignment, size_t size)
{
	count();
	void *p = __libc_memalign(alignment, size);
	if (p == nullptr)
		return ENOMEM;
	*out = p;
	return 0;
}
}
