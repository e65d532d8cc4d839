// Benchmark (not a test): frame-index hand-off throughput between two threads, our lock-free SPSC ring
// against a mutex + condition-variable deque measured in the same run on the same machine.
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "core/spsc_ring.hpp"

using namespace stereod;
using Clock = std::chrono::steady_clock;

namespace {

/// The naive baseline: what one writes first, a locked deque with a bound.
class LockedQueue
{
public:
	explicit LockedQueue(size_t capacity) : capacity_(capacity) {}
	void push(uint32_t v)
	{
		std::unique_lock lock(m_);
		not_full_.wait(lock, [&] { return q_.size() < capacity_; });
		q_.push_back(v);
		not_empty_.notify_one();
	}
	std::optional<uint32_t> pop()
	{
		std::unique_lock lock(m_);
		not_empty_.wait(lock, [&] { return !q_.empty() || closed_; });
		if (q_.empty())
			return std::nullopt;
		const uint32_t v = q_.front();
		q_.pop_front();
		not_full_.notify_one();
		return v;
	}
	void close()
	{
		std::lock_guard lock(m_);
		closed_ = true;
		not_empty_.notify_all();
	}

private:
	size_t capacity_;
	std::mutex m_;
	std::condition_variable not_full_, not_empty_;
	std::deque<uint32_t> q_;
	bool closed_ = false;
};

struct Result {
	double seconds;
	uint64_t received;
	uint64_t dropped;
};

template <typename Push, typename Pop, typename Close>
Result run(uint64_t count, Push push, Pop pop, Close close)
{
	uint64_t received = 0, checksum = 0;
	const auto start = Clock::now();
	std::thread consumer([&] {
		while (auto v = pop()) {
			++received;
			checksum += *v;
		}
	});
	uint64_t dropped = 0;
	for (uint64_t i = 0; i < count; ++i)
		dropped += push(static_cast<uint32_t>(i)) ? 0 : 1;
	close();
	consumer.join();
	const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
	if (checksum == 42) // keep the sum alive
		std::puts("");
	return {seconds, received, dropped};
}

void row(const char *name, uint64_t count, const Result &r)
{
	std::printf("| %-34s | %9.2f | %8.1f | %10llu | %8llu |\n", name, static_cast<double>(count) / r.seconds / 1e6,
		    r.seconds * 1e9 / static_cast<double>(count), static_cast<unsigned long long>(r.received),
		    static_cast<unsigned long long>(r.dropped));
}

} // namespace

int main(int argc, char **argv)
{
	CLI::App app{"ring hand-off throughput: SPSC ring vs mutex+deque"};
	uint64_t count = 5'000'000;
	size_t capacity = 8;
	int repeats = 3;
	app.add_option("-n,--count", count, "hand-offs per run");
	app.add_option("--capacity", capacity, "queue capacity (the daemon's ring_capacity default is 8)");
	app.add_option("-r,--repeats", repeats, "runs per variant; the best is shown");
	CLI11_PARSE(app, argc, argv);

	std::printf("hand-offs: %llu per run, capacity %zu, best of %d runs, %u hardware threads\n\n",
		    static_cast<unsigned long long>(count), capacity, repeats, std::thread::hardware_concurrency());
	std::printf("| %-34s | %9s | %8s | %10s | %8s |\n", "variant", "Mops/s", "ns/op", "received", "dropped");
	std::printf("|%s|%s|%s|%s|%s|\n", std::string(36, '-').c_str(), std::string(11, '-').c_str(),
		    std::string(10, '-').c_str(), std::string(12, '-').c_str(), std::string(10, '-').c_str());

	auto best = [&](auto once) {
		Result b{1e30, 0, 0};
		for (int i = 0; i < repeats; ++i) {
			const Result r = once();
			if (r.seconds < b.seconds)
				b = r;
		}
		return b;
	};
	auto ring_run = [&](OverflowPolicy policy) {
		return [&, policy] {
			SpscRing<uint32_t> ring(capacity, policy);
			uint32_t evicted = 0;
			return run(
				count,
				[&](uint32_t v) {
					return ring.push(v, evicted) != SpscRing<uint32_t>::PushResult::PushedEvicted;
				},
				[&] { return ring.pop(); }, [&] { ring.close(); });
		};
	};
	row("SpscRing, block (offline policy)", count, best(ring_run(OverflowPolicy::Block)));
	row("SpscRing, drop-oldest (live policy)", count, best(ring_run(OverflowPolicy::DropOldest)));
	row("baseline: mutex + condvar deque", count, best([&] {
		    LockedQueue q(capacity);
		    return run(
			    count,
			    [&](uint32_t v) {
				    q.push(v);
				    return true;
			    },
			    [&] { return q.pop(); }, [&] { q.close(); });
	    }));
	std::printf("\nreceived + dropped = hand-offs in every row; drop-oldest drops only when the consumer lags.\n");
	return 0;
}
