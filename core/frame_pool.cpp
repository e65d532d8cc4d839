#include "core/frame_pool.hpp"

#include <stdexcept>
#include <utility>

namespace stereod {

FrameHandle::FrameHandle(FrameHandle &&other) noexcept
	: pool_(std::exchange(other.pool_, nullptr)), index_(other.index_)
{
}

FrameHandle &FrameHandle::operator=(FrameHandle &&other) noexcept
{
	if (this != &other) {
		reset();
		pool_ = std::exchange(other.pool_, nullptr);
		index_ = other.index_;
	}
	return *this;
}

FrameHandle::~FrameHandle()
{
	reset();
}

StereoFrame &FrameHandle::operator*() const noexcept
{
	return pool_->frames_[index_];
}

StereoFrame *FrameHandle::operator->() const noexcept
{
	return &pool_->frames_[index_];
}

uint32_t FrameHandle::release() noexcept
{
	pool_ = nullptr;
	return index_;
}

void FrameHandle::reset() noexcept
{
	if (pool_)
		std::exchange(pool_, nullptr)->give_back(index_);
}

FramePool::FramePool(size_t size, const FrameGeometry &geometry)
	: geometry_(geometry), frames_(size), next_(std::make_unique<std::atomic<uint32_t>[]>(size)),
	  top_(pack(0, size ? 0 : kNone)), free_count_(size)
{
	if (size == 0 || size >= kNone)
		throw std::invalid_argument("frame pool size out of range");
	if (geometry.width <= 0 || geometry.height <= 0)
		throw std::invalid_argument("frame pool needs a positive image size");
	for (size_t i = 0; i < size; ++i) {
		frames_[i].allocate(geometry);
		next_[i].store(i + 1 < size ? static_cast<uint32_t>(i + 1) : kNone, std::memory_order_relaxed);
	}
}

std::optional<FrameHandle> FramePool::try_acquire() noexcept
{
	uint64_t top = top_.load(std::memory_order_acquire);
	for (;;) {
		const auto index = static_cast<uint32_t>(top);
		if (index == kNone)
			return std::nullopt;
		const uint32_t next = next_[index].load(std::memory_order_relaxed);
		const auto tag = static_cast<uint32_t>(top >> 32) + 1;
		if (top_.compare_exchange_weak(top, pack(tag, next), std::memory_order_acq_rel)) {
			free_count_.fetch_sub(1, std::memory_order_relaxed);
			frames_[index].reset_metadata();
			return FrameHandle(this, index);
		}
	}
}

FrameHandle FramePool::adopt(uint32_t index) noexcept
{
	return FrameHandle(this, index);
}

void FramePool::give_back(uint32_t index) noexcept
{
	uint64_t top = top_.load(std::memory_order_acquire);
	for (;;) {
		next_[index].store(static_cast<uint32_t>(top), std::memory_order_relaxed);
		const auto tag = static_cast<uint32_t>(top >> 32) + 1;
		if (top_.compare_exchange_weak(top, pack(tag, index), std::memory_order_acq_rel))
			break;
	}
	free_count_.fetch_add(1, std::memory_order_relaxed);
	releases_.fetch_add(1, std::memory_order_release);
	releases_.notify_all();
}

void FramePool::wake_waiters() noexcept
{
	releases_.fetch_add(1, std::memory_order_release);
	releases_.notify_all();
}

} // namespace stereod
