#pragma once
// A bounded single-producer/single-consumer ring between the capture thread and the processing side.
//
// Values are small trivially copyable handles (frame-pool slot indices), stored in atomics so that the one
// race the design allows -- the producer evicting the oldest entry while the consumer is taking it -- is
// well defined. Both sides advance `head_` with a compare-and-swap; whoever wins owns the value, the loser
// retries. Nothing here allocates after construction.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string_view>
#include <type_traits>

namespace stereod {

enum class OverflowPolicy : uint8_t {
	DropOldest, ///< live sources: the newest frame always gets in, the oldest queued one is evicted
	Block,	    ///< offline replay: the producer waits, nothing is ever lost
};

std::string_view to_string(OverflowPolicy policy) noexcept;

struct RingCounters {
	uint64_t pushed = 0;
	uint64_t popped = 0;
	uint64_t evicted = 0;	     ///< values dropped by DropOldest (each handed back to the producer)
	uint64_t producer_waits = 0; ///< times Block made the producer wait
};

template <typename T>
class SpscRing
{
	static_assert(std::is_trivially_copyable_v<T>);
	static_assert(std::atomic<T>::is_always_lock_free);

public:
	enum class PushResult : uint8_t {
		Pushed,
		PushedEvicted, ///< pushed; the oldest value was evicted and written to `evicted`
		Closed,	       ///< the ring is closed; the value was not pushed
	};

	SpscRing(size_t capacity, OverflowPolicy policy)
		: capacity_(capacity), policy_(policy), slots_(std::make_unique<std::atomic<T>[]>(capacity))
	{
		if (capacity == 0)
			throw std::invalid_argument("ring capacity must be at least 1");
	}

	SpscRing(const SpscRing &) = delete;
	SpscRing &operator=(const SpscRing &) = delete;

	/// Producer side. Under Block it waits for room (or close()); under DropOldest it never waits.
	PushResult push(T value, T &evicted)
	{
		PushResult result = PushResult::Pushed;
		const uint64_t tail = tail_.load(std::memory_order_relaxed);
		for (;;) {
			if (closed_.load(std::memory_order_acquire))
				return PushResult::Closed;
			uint64_t head = head_.load(std::memory_order_acquire);
			if (tail - head < capacity_)
				break;
			if (policy_ == OverflowPolicy::Block) {
				producer_waits_.fetch_add(1, std::memory_order_relaxed);
				wait_for_change([&] {
					return closed_.load(std::memory_order_acquire) ||
					       tail - head_.load(std::memory_order_acquire) < capacity_;
				});
				continue;
			}
			// The slot at `head` was written by this thread, so reading it here is safe; the CAS decides
			// whether we or the consumer own it.
			const T oldest = slots_[head % capacity_].load(std::memory_order_relaxed);
			if (head_.compare_exchange_strong(head, head + 1, std::memory_order_acq_rel)) {
				evicted = oldest;
				evicted_.fetch_add(1, std::memory_order_relaxed);
				result = PushResult::PushedEvicted;
				break;
			}
		}
		slots_[tail % capacity_].store(value, std::memory_order_relaxed);
		tail_.store(tail + 1, std::memory_order_release);
		signal();
		pushed_.fetch_add(1, std::memory_order_relaxed);
		return result;
	}

	/// Consumer side, never waits.
	std::optional<T> try_pop()
	{
		for (;;) {
			uint64_t head = head_.load(std::memory_order_acquire);
			const uint64_t tail = tail_.load(std::memory_order_acquire);
			if (head == tail)
				return std::nullopt;
			const T value = slots_[head % capacity_].load(std::memory_order_relaxed);
			if (head_.compare_exchange_strong(head, head + 1, std::memory_order_acq_rel)) {
				signal();
				popped_.fetch_add(1, std::memory_order_relaxed);
				return value;
			}
		}
	}

	/// Consumer side: waits for a value; returns nullopt once the ring is closed and drained.
	std::optional<T> pop()
	{
		for (;;) {
			if (auto value = try_pop())
				return value;
			if (closed_.load(std::memory_order_acquire)) {
				// A push may have landed between try_pop and the close check: drain it first.
				if (auto value = try_pop())
					return value;
				return std::nullopt;
			}
			wait_for_change([&] {
				return closed_.load(std::memory_order_acquire) ||
				       head_.load(std::memory_order_acquire) != tail_.load(std::memory_order_acquire);
			});
		}
	}

	/// Wakes both sides; later pushes fail, pops drain what is left.
	void close()
	{
		closed_.store(true, std::memory_order_release);
		signal();
	}

	[[nodiscard]] bool closed() const { return closed_.load(std::memory_order_acquire); }
	[[nodiscard]] size_t capacity() const { return capacity_; }
	[[nodiscard]] OverflowPolicy policy() const { return policy_; }
	[[nodiscard]] size_t size() const
	{
		return static_cast<size_t>(tail_.load(std::memory_order_acquire) -
					   head_.load(std::memory_order_acquire));
	}

	[[nodiscard]] RingCounters counters() const
	{
		return {pushed_.load(std::memory_order_relaxed), popped_.load(std::memory_order_relaxed),
			evicted_.load(std::memory_order_relaxed), producer_waits_.load(std::memory_order_relaxed)};
	}

private:
	// Every push, pop and close bumps `events_`; a waiter reads it, re-checks its condition and sleeps only
	// while `events_` is unchanged, so no wake-up can be missed. notify is cheap when nobody waits.
	void signal()
	{
		events_.fetch_add(1, std::memory_order_release);
		events_.notify_all();
	}

	template <typename Ready>
	void wait_for_change(Ready ready)
	{
		// Spin briefly first: the other side usually acts within a microsecond or two, and sleeping in
		// the kernel (and being woken) costs more than that.
		for (int i = 0; i < kSpinsBeforeSleep; ++i) {
			if (ready())
				return;
			cpu_relax();
		}
		const uint32_t seen = events_.load(std::memory_order_acquire);
		if (!ready())
			events_.wait(seen, std::memory_order_acquire);
	}

	static void cpu_relax() noexcept
	{
#if defined(__x86_64__) || defined(__i386__)
		__builtin_ia32_pause();
#elif defined(__aarch64__) || defined(__arm__)
		asm volatile("yield" ::: "memory");
#endif
	}

	static constexpr int kSpinsBeforeSleep = 2000;

	const size_t capacity_;
	const OverflowPolicy policy_;
	std::unique_ptr<std::atomic<T>[]> slots_;
	alignas(64) std::atomic<uint64_t> head_{0}; ///< next index to read
	alignas(64) std::atomic<uint64_t> tail_{0}; ///< next index to write
	alignas(64) std::atomic<bool> closed_{false};
	std::atomic<uint32_t> events_{0};
	std::atomic<uint64_t> pushed_{0};
	std::atomic<uint64_t> popped_{0};
	std::atomic<uint64_t> evicted_{0};
	std::atomic<uint64_t> producer_waits_{0};
};

} // namespace stereod
