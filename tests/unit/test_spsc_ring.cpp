#include <gtest/gtest.h>

#include <thread>
#include <vector>

#include "core/spsc_ring.hpp"

using stereod::OverflowPolicy;
using stereod::SpscRing;
using Ring = SpscRing<uint32_t>;

TEST(SpscRing, PopsInPushOrder)
{
	Ring ring(4, OverflowPolicy::Block);
	uint32_t evicted = 0;
	for (uint32_t i = 0; i < 4; ++i)
		EXPECT_EQ(ring.push(i, evicted), Ring::PushResult::Pushed);
	EXPECT_EQ(ring.size(), 4U);
	for (uint32_t i = 0; i < 4; ++i)
		EXPECT_EQ(ring.try_pop(), i);
	EXPECT_FALSE(ring.try_pop().has_value());
}

TEST(SpscRing, DropOldestEvictsTheOldestAndCountsIt)
{
	Ring ring(3, OverflowPolicy::DropOldest);
	uint32_t evicted = 99;
	for (uint32_t i = 0; i < 3; ++i)
		ASSERT_EQ(ring.push(i, evicted), Ring::PushResult::Pushed);
	EXPECT_EQ(ring.push(3, evicted), Ring::PushResult::PushedEvicted);
	EXPECT_EQ(evicted, 0U);
	EXPECT_EQ(ring.push(4, evicted), Ring::PushResult::PushedEvicted);
	EXPECT_EQ(evicted, 1U);
	EXPECT_EQ(ring.counters().evicted, 2U);
	EXPECT_EQ(ring.try_pop(), 2U);
	EXPECT_EQ(ring.try_pop(), 3U);
	EXPECT_EQ(ring.try_pop(), 4U);
}

TEST(SpscRing, CloseWakesAConsumerAndDrains)
{
	Ring ring(2, OverflowPolicy::Block);
	uint32_t evicted = 0;
	ring.push(7, evicted);
	std::thread closer([&] {
		std::this_thread::sleep_for(std::chrono::milliseconds(20));
		ring.close();
	});
	EXPECT_EQ(ring.pop(), 7U);
	EXPECT_FALSE(ring.pop().has_value()); // waits until close, then reports the end
	closer.join();
	EXPECT_EQ(ring.push(8, evicted), Ring::PushResult::Closed);
}

TEST(SpscRing, CloseWakesABlockedProducer)
{
	Ring ring(1, OverflowPolicy::Block);
	uint32_t evicted = 0;
	ring.push(1, evicted);
	std::thread closer([&] {
		std::this_thread::sleep_for(std::chrono::milliseconds(20));
		ring.close();
	});
	EXPECT_EQ(ring.push(2, evicted), Ring::PushResult::Closed);
	closer.join();
}

// Bounded stress: under Block nothing is lost or duplicated, and order holds.
TEST(SpscRingStress, BlockLosesNothing)
{
	constexpr uint32_t kCount = 300000;
	Ring ring(8, OverflowPolicy::Block);
	std::vector<uint32_t> received;
	received.reserve(kCount);
	std::thread consumer([&] {
		while (auto v = ring.pop())
			received.push_back(*v);
	});
	uint32_t evicted = 0;
	for (uint32_t i = 0; i < kCount; ++i)
		ASSERT_EQ(ring.push(i, evicted), Ring::PushResult::Pushed);
	ring.close();
	consumer.join();
	ASSERT_EQ(received.size(), kCount);
	for (uint32_t i = 0; i < kCount; ++i)
		ASSERT_EQ(received[i], i);
	EXPECT_EQ(ring.counters().evicted, 0U);
}

// Bounded stress: under DropOldest every value is either consumed or handed back as evicted, exactly once,
// and the eviction counter equals the number handed back.
TEST(SpscRingStress, DropOldestCountsEveryDropExactly)
{
	constexpr uint32_t kCount = 300000;
	Ring ring(4, OverflowPolicy::DropOldest);
	std::vector<uint32_t> received;
	std::thread consumer([&] {
		uint64_t spin = 0;
		while (auto v = ring.pop()) {
			received.push_back(*v);
			for (int i = 0; i < 50; ++i) // a slower consumer, so the ring overflows often
				spin += static_cast<uint64_t>(i);
		}
		(void)spin;
	});
	std::vector<uint32_t> evicted_values;
	uint32_t evicted = 0;
	for (uint32_t i = 0; i < kCount; ++i)
		if (ring.push(i, evicted) == Ring::PushResult::PushedEvicted)
			evicted_values.push_back(evicted);
	ring.close();
	consumer.join();

	std::vector<uint8_t> seen(kCount, 0);
	for (uint32_t v : received)
		++seen[v];
	for (uint32_t v : evicted_values)
		++seen[v];
	for (uint32_t i = 0; i < kCount; ++i)
		ASSERT_EQ(seen[i], 1) << "value " << i;
	EXPECT_EQ(ring.counters().evicted, evicted_values.size());
	EXPECT_GT(evicted_values.size(), 0U) << "the stress should overflow the ring at least once";
	for (size_t i = 1; i < received.size(); ++i)
		ASSERT_LT(received[i - 1], received[i]) << "consumed values keep their order";
}
