#include <gtest/gtest.h>

#include <thread>
#include <vector>

#include "core/frame_pool.hpp"

using namespace stereod;

namespace {
FrameGeometry small_geometry()
{
	return {64, 48, PixelFormat::Bgr8, true, false, false, 30};
}
} // namespace

TEST(FramePool, AllocatesEveryBufferUpFront)
{
	FramePool pool(3, small_geometry());
	auto frame = pool.try_acquire();
	ASSERT_TRUE(frame);
	EXPECT_EQ((*frame)->left.size(), cv::Size(64, 48));
	EXPECT_EQ((*frame)->right.type(), CV_8UC3);
	EXPECT_TRUE((*frame)->depth.empty());
}

TEST(FramePool, ExhaustsAndRecycles)
{
	FramePool pool(2, small_geometry());
	auto a = pool.try_acquire();
	auto b = pool.try_acquire();
	ASSERT_TRUE(a && b);
	EXPECT_NE(a->index(), b->index());
	EXPECT_FALSE(pool.try_acquire().has_value());
	EXPECT_EQ(pool.free_count(), 0U);
	const uchar *buffer = (*a)->left.data;
	a.reset();
	auto c = pool.try_acquire();
	ASSERT_TRUE(c);
	EXPECT_EQ((*c)->left.data, buffer) << "the same preallocated buffer comes back";
}

TEST(FramePool, ReleaseThroughIndexRoundTrip)
{
	FramePool pool(1, small_geometry());
	auto frame = pool.try_acquire();
	const uint32_t index = frame->release();
	EXPECT_FALSE(pool.try_acquire().has_value());
	pool.adopt(index).reset();
	EXPECT_TRUE(pool.try_acquire().has_value());
}

TEST(FramePoolStress, ConcurrentReturnsLoseNoSlot)
{
	FramePool pool(8, small_geometry());
	std::vector<std::thread> threads;
	for (int t = 0; t < 4; ++t)
		threads.emplace_back([&] {
			for (int i = 0; i < 20000; ++i)
				if (auto frame = pool.try_acquire())
					frame->reset();
		});
	for (auto &t : threads)
		t.join();
	EXPECT_EQ(pool.free_count(), 8U);
	std::vector<FrameHandle> all;
	while (auto frame = pool.try_acquire())
		all.push_back(std::move(*frame));
	EXPECT_EQ(all.size(), 8U);
}
