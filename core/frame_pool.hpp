#pragma once
// A fixed set of preallocated frames. The capture thread takes a free slot, fills it in place and passes the
// slot index through the ring; whoever holds the FrameHandle last gives the slot back. The free list is a
// lock-free stack of indices (tagged against ABA), so neither taking nor returning a slot allocates or locks.
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "core/frame.hpp"

namespace stereod {

class FramePool;

/// Unique ownership of one pool slot; returns it to the pool when destroyed.
class FrameHandle
{
public:
	FrameHandle() = default;
	FrameHandle(FrameHandle &&other) noexcept;
	FrameHandle &operator=(FrameHandle &&other) noexcept;
	FrameHandle(const FrameHandle &) = delete;
	FrameHandle &operator=(const FrameHandle &) = delete;
	~FrameHandle();

	[[nodiscard]] explicit operator bool() const noexcept { return pool_ != nullptr; }
	StereoFrame &operator*() const noexcept;
	StereoFrame *operator->() const noexcept;
	[[nodiscard]] uint32_t index() const noexcept { return index_; }

	/// Gives up ownership without returning the slot, for handing the index through the ring.
	uint32_t release() noexcept;
	void reset() noexcept;

private:
	friend class FramePool;
	FrameHandle(FramePool *pool, uint32_t index) noexcept : pool_(pool), index_(index) {}

	FramePool *pool_ = nullptr;
	uint32_t index_ = 0;
};

class FramePool
{
public:
	FramePool(size_t size, const FrameGeometry &geometry);
	FramePool(const FramePool &) = delete;
	FramePool &operator=(const FramePool &) = delete;

	/// A free frame, or nothing when every frame is in use. Never blocks, never allocates.
	std::optional<FrameHandle> try_acquire() noexcept;
	/// Re-owns an index that went through the ring (see FrameHandle::release()).
	FrameHandle adopt(uint32_t index) noexcept;

	[[nodiscard]] size_t size() const noexcept { return frames_.size(); }
	[[nodiscard]] size_t free_count() const noexcept { return free_count_.load(std::memory_order_relaxed); }
	[[nodiscard]] const FrameGeometry &geometry() const noexcept { return geometry_; }
	/// Waits until a frame is free or `give_up()` says stop; checks every millisecond (offline path only).
	template <typename GiveUp>
	std::optional<FrameHandle> acquire_waiting(GiveUp give_up)
	{
		for (;;) {
			if (auto frame = try_acquire())
				return frame;
			if (give_up())
				return std::nullopt;
			const uint32_t seen = releases_.load(std::memory_order_acquire);
			if (free_count() == 0)
				releases_.wait(seen, std::memory_order_acquire);
		}
	}
	/// Wakes acquire_waiting() so it can consult its give_up predicate.
	void wake_waiters() noexcept;

private:
	friend class FrameHandle;
	void give_back(uint32_t index) noexcept;

	static constexpr uint32_t kNone = UINT32_MAX;
	static uint64_t pack(uint32_t tag, uint32_t index) noexcept { return (uint64_t{tag} << 32) | index; }

	FrameGeometry geometry_;
	std::vector<StereoFrame> frames_;
	std::unique_ptr<std::atomic<uint32_t>[]> next_; ///< free-list links
	std::atomic<uint64_t> top_;			///< tag << 32 | index of the first free slot
	std::atomic<size_t> free_count_;
	std::atomic<uint32_t> releases_{0};
};

} // namespace stereod
