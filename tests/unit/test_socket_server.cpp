// The results socket with real clients on a real Unix socket.
#include <gtest/gtest.h>

#include <chrono>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <thread>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "core/clock.hpp"
#include "daemon/socket_server.hpp"

using namespace stereod;
using namespace stereod::daemon;
namespace fs = std::filesystem;

namespace {

std::string socket_path(const std::string &name)
{
	return (fs::temp_directory_path() / ("stereod-" + std::to_string(::getpid()) + "-" + name + ".sock")).string();
}

int connect_to(const std::string &path)
{
	const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	const sockaddr_un addr = unix_socket_address(path);
	EXPECT_EQ(::connect(fd, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)), 0) << std::strerror(errno);
	timeval tv{2, 0};
	::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
	return fd;
}

/// Reads lines until `count` arrived or the peer closes / times out.
std::vector<std::string> read_lines(int fd, size_t count)
{
	std::vector<std::string> lines;
	std::string buffer;
	char chunk[4096];
	while (lines.size() < count) {
		const ssize_t n = ::recv(fd, chunk, sizeof(chunk), 0);
		if (n <= 0)
			break;
		buffer.append(chunk, static_cast<size_t>(n));
		size_t pos = 0;
		while ((pos = buffer.find('\n')) != std::string::npos) {
			lines.push_back(buffer.substr(0, pos));
			buffer.erase(0, pos + 1);
		}
	}
	return lines;
}

template <typename Predicate>
bool eventually(Predicate p, int ms = 3000)
{
	for (int i = 0; i < ms / 10; ++i) {
		if (p())
			return true;
		std::this_thread::sleep_for(std::chrono::milliseconds(10));
	}
	return p();
}

} // namespace

TEST(SocketServer, EveryClientGetsEveryMessageInOrder)
{
	const auto path = socket_path("fanout");
	SocketServer server({path, 0660, 1000, 4096});
	server.set_greeting("{\"type\":\"hello\"}");
	std::vector<int> clients = {connect_to(path), connect_to(path), connect_to(path)};
	ASSERT_TRUE(eventually([&] { return server.stats().clients == 3; }));
	for (int i = 0; i < 200; ++i)
		server.publish("{\"n\":" + std::to_string(i) + "}");
	for (int fd : clients) {
		const auto lines = read_lines(fd, 201);
		ASSERT_EQ(lines.size(), 201U);
		EXPECT_EQ(lines[0], "{\"type\":\"hello\"}");
		for (int i = 0; i < 200; ++i)
			ASSERT_EQ(lines[static_cast<size_t>(i + 1)], "{\"n\":" + std::to_string(i) + "}");
		::close(fd);
	}
}

TEST(SocketServer, SocketFileHasTheConfiguredMode)
{
	const auto path = socket_path("mode");
	SocketServer server({path, 0660, 10, 4096});
	struct stat st {
	};
	ASSERT_EQ(::stat(path.c_str(), &st), 0);
	EXPECT_TRUE(S_ISSOCK(st.st_mode));
	EXPECT_EQ(st.st_mode & 0777, 0660U);
}

namespace {

struct Received {
	int messages = 0;	///< data messages received
	uint64_t told_lost = 0; ///< sum of the `dropped` counts in lag messages
	int last = -1;
	bool in_order = true;
};

Received tally(const std::vector<std::string> &lines)
{
	Received r;
	for (const auto &line : lines) {
		const auto j = nlohmann::json::parse(line);
		if (j.value("type", "") == "lag") {
			r.told_lost += j["dropped"].get<uint64_t>();
			continue;
		}
		const int n = j["n"].get<int>();
		r.in_order = r.in_order && n > r.last;
		r.last = n;
		++r.messages;
	}
	return r;
}

} // namespace

TEST(SocketServer, SlowClientLosesItsOldestAndIsToldNeverStallingOthers)
{
	const auto path = socket_path("slow");
	SocketServer server({path, 0660, 16, 4096});
	const int slow = connect_to(path);
	const int fast = connect_to(path);
	ASSERT_TRUE(eventually([&] { return server.stats().clients == 2; }));
	// Large messages fill the slow client's socket buffer quickly; it never reads during publishing.
	constexpr int kMessages = 2000;
	const std::string padding(8000, 'x');
	std::vector<std::string> fast_lines;
	std::thread reader([&] { fast_lines = read_lines(fast, 100000); });
	const int64_t start = monotonic_ns();
	for (int i = 0; i < kMessages; ++i) {
		server.publish("{\"n\":" + std::to_string(i) + ",\"pad\":\"" + padding + "\"}");
		// About 5000 messages a second: a reader keeps up, one that never reads cannot.
		std::this_thread::sleep_for(std::chrono::microseconds(200));
	}
	const double publish_ms = static_cast<double>(monotonic_ns() - start) * 1e-6;
	EXPECT_LT(publish_ms, 5000.0) << "publish() must not wait for the slow client";
	const auto slow_lines = read_lines(slow, 100000); // now it reads: what is queued, then the timeout
	::shutdown(fast, SHUT_RDWR);
	reader.join();

	const Received f = tally(fast_lines), s = tally(slow_lines);
	// Exact accounting for both: every message was either received or reported lost.
	EXPECT_EQ(static_cast<uint64_t>(f.messages) + f.told_lost, static_cast<uint64_t>(kMessages));
	EXPECT_EQ(static_cast<uint64_t>(s.messages) + s.told_lost, static_cast<uint64_t>(kMessages));
	EXPECT_EQ(f.told_lost + s.told_lost, server.stats().messages_dropped);
	EXPECT_GT(s.told_lost, 1000U) << "the client that never read lost most of them";
	EXPECT_LT(f.told_lost, s.told_lost / 10) << "the reading client lost little or nothing";
	EXPECT_TRUE(f.in_order && s.in_order);
	EXPECT_EQ(s.last, kMessages - 1) << "the newest message always gets through";
	::close(slow);
	::close(fast);
}

TEST(SocketServer, ClientThatFloodsUsIsDroppedAndCounted)
{
	const auto path = socket_path("flood");
	SocketServer server({path, 0660, 16, 1024});
	const int bad = connect_to(path);
	const int good = connect_to(path);
	ASSERT_TRUE(eventually([&] { return server.stats().clients == 2; }));
	const std::string junk(4096, 'j');
	(void)!::send(bad, junk.data(), junk.size(), MSG_NOSIGNAL);
	ASSERT_TRUE(eventually([&] { return server.stats().clients_dropped == 1; }));
	EXPECT_EQ(server.stats().clients, 1U);
	server.publish("{\"still\":1}");
	EXPECT_EQ(read_lines(good, 1), std::vector<std::string>{"{\"still\":1}"});
	::close(bad);
	::close(good);
}

TEST(SocketServer, HalfClosedClientKeepsReceiving)
{
	const auto path = socket_path("halfclose");
	SocketServer server({path, 0660, 16, 1024});
	const int fd = connect_to(path);
	ASSERT_TRUE(eventually([&] { return server.stats().clients == 1; }));
	::shutdown(fd, SHUT_WR); // like `socat -` after its standard input ends
	std::this_thread::sleep_for(std::chrono::milliseconds(50));
	server.publish("{\"a\":1}");
	EXPECT_EQ(read_lines(fd, 1), std::vector<std::string>{"{\"a\":1}"});
	::close(fd);
}

TEST(SocketServer, ReplacesAStaleSocketButNotALiveOne)
{
	const auto path = socket_path("stale");
	{
		// A socket file nobody listens on, as a crashed daemon leaves behind.
		const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
		const sockaddr_un addr = unix_socket_address(path);
		ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)), 0);
		::close(fd);
	}
	SocketServer first({path, 0660, 16, 1024});
	EXPECT_THROW(SocketServer({path, 0660, 16, 1024}), std::runtime_error);
	const auto regular = socket_path("regular-file");
	std::ofstream(regular) << "x";
	EXPECT_THROW(SocketServer({regular, 0660, 16, 1024}), std::runtime_error);
	fs::remove(regular);
}

// Defects found by a hostile probe (issue 17, section 8).
TEST(SocketServerDefects, DestructionUnderConnectionChurnDoesNotCrash)
{
	// ~SocketServer iterated clients_ while a failed send erased from it: SIGSEGV in 2 of 22 runs with 200
	// clients connecting and disconnecting. Here: clients that hang up without reading, with messages queued
	// for them, destroyed mid-churn, many times.
	for (int round = 0; round < 20; ++round) {
		const auto path = socket_path("churn" + std::to_string(round));
		std::atomic<bool> stop{false};
		auto server = std::make_unique<SocketServer>(SocketServerOptions{path, 0660, 64, 4096});
		std::thread churn([&] {
			while (!stop.load()) {
				const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
				const sockaddr_un addr = unix_socket_address(path);
				if (::connect(fd, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)) == 0) {
					int tiny = 1;
					::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &tiny, sizeof(tiny));
				}
				::close(fd);
			}
		});
		std::vector<int> held;
		for (int i = 0; i < 20; ++i)
			held.push_back(connect_to(path));
		for (int i = 0; i < 200; ++i)
			server->publish(std::string(2000, 'x'));
		for (size_t i = 0; i < held.size(); i += 2)
			::close(held[i]); // peers gone: their flush fails inside the destructor
		server.reset();
		stop.store(true);
		churn.join();
		for (size_t i = 1; i < held.size(); i += 2)
			::close(held[i]);
		EXPECT_FALSE(fs::exists(path));
	}
}

TEST(SocketServerDefects, ClientsBeyondTheLimitAreRefusedWithAReason)
{
	const auto path = socket_path("limit");
	SocketServerOptions options{path, 0660, 16, 4096};
	options.max_clients = 3;
	SocketServer server(options);
	server.set_greeting("{\"type\":\"hello\"}");
	std::vector<int> clients;
	for (int i = 0; i < 3; ++i)
		clients.push_back(connect_to(path));
	ASSERT_TRUE(eventually([&] { return server.stats().clients == 3; }));
	const int refused = connect_to(path);
	const auto lines = read_lines(refused, 2);
	ASSERT_EQ(lines.size(), 1U) << "the refused client should get one line and be closed";
	EXPECT_EQ(nlohmann::json::parse(lines[0]).at("type"), "error");
	EXPECT_NE(lines[0].find("too many clients"), std::string::npos);
	EXPECT_EQ(server.stats().clients_refused, 1U);
	EXPECT_EQ(server.stats().clients, 3U);
	for (int fd : clients)
		::close(fd);
	::close(refused);
}

TEST(SocketServerDefects, OutOfDescriptorsRefusesInsteadOfSpinning)
{
	// With descriptors exhausted, accept() failed with EMFILE forever: the socket thread spun at 100 %, new
	// clients never got hello, nothing was logged.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
	// The sanitizer runtimes themselves need descriptors (UBSan's type checks read /proc/self/maps): with none
	// left they report errors of their own. The plain build runs this test.
	GTEST_SKIP() << "not under sanitizers: their runtime needs file descriptors";
#endif
	const auto path = socket_path("emfile");
	SocketServer server({path, 0660, 16, 4096});
	server.set_greeting("{\"type\":\"hello\"}");
	rlimit old{};
	::getrlimit(RLIMIT_NOFILE, &old);
	std::vector<int> filler;
	rlimit tight = old;
	tight.rlim_cur = 64;
	ASSERT_EQ(::setrlimit(RLIMIT_NOFILE, &tight), 0);
	int probe = 0;
	while ((probe = ::open("/dev/null", O_RDONLY | O_CLOEXEC)) >= 0)
		filler.push_back(probe);
	// One descriptor back for the client side of the connection.
	::close(filler.back());
	filler.pop_back();
	const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	ASSERT_GE(fd, 0);
	const sockaddr_un addr = unix_socket_address(path);
	ASSERT_EQ(::connect(fd, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)), 0);
	timeval tv{3, 0};
	::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
	const auto lines = read_lines(fd, 2);
	ASSERT_EQ(lines.size(), 1U);
	EXPECT_NE(lines[0].find("out of file descriptors"), std::string::npos) << lines[0];
	EXPECT_EQ(server.stats().clients_refused, 1U);
	// The thread is not spinning: its CPU time stays flat over half a second.
	timespec before{}, after{};
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &before);
	std::this_thread::sleep_for(std::chrono::milliseconds(500));
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &after);
	const double cpu = static_cast<double>(after.tv_sec - before.tv_sec) +
			   1e-9 * static_cast<double>(after.tv_nsec - before.tv_nsec);
	EXPECT_LT(cpu, 0.2) << "the socket thread spins";
	::close(fd);
	for (int f : filler)
		::close(f);
	::setrlimit(RLIMIT_NOFILE, &old);
	// Descriptors back: a new client is served again.
	const int fresh = connect_to(path);
	const auto hello = read_lines(fresh, 1);
	ASSERT_EQ(hello.size(), 1U);
	EXPECT_NE(hello[0].find("hello"), std::string::npos);
	::close(fresh);
}

TEST(SocketServerDefects, QueueIsBoundedInBytes)
{
	// client_queue = 1000000 let a client that never reads grow memory by 1.6 MB/s.
	const auto path = socket_path("bytes");
	SocketServerOptions options{path, 0660, 1000000, 4096};
	options.client_queue_bytes = 64 * 1024;
	SocketServer server(options);
	const int idle = connect_to(path);
	ASSERT_TRUE(eventually([&] { return server.stats().clients == 1; }));
	for (int i = 0; i < 2000; ++i)
		server.publish(std::string(1000, 'y'));
	// At most 64 KiB queued (plus what the socket buffer took): the rest was dropped and counted.
	EXPECT_TRUE(eventually([&] { return server.stats().messages_dropped > 1000; }))
		<< server.stats().messages_dropped;
	::close(idle);
}

TEST(SocketServerAccess, PeerRuleByUserAndGroups)
{
	SocketServerOptions options;
	constexpr uid_t kSelf = 990;
	// No lists: anyone the file mode lets connect.
	EXPECT_TRUE(peer_allowed(1234, {1234}, options, kSelf));
	options.allow_uids = {1001};
	options.allow_gids = {44};
	EXPECT_TRUE(peer_allowed(1001, {1001}, options, kSelf)) << "listed user";
	EXPECT_TRUE(peer_allowed(1002, {1002, 44}, options, kSelf)) << "supplementary group listed";
	EXPECT_TRUE(peer_allowed(1003, {44}, options, kSelf)) << "primary group listed";
	EXPECT_FALSE(peer_allowed(1004, {1004, 100}, options, kSelf));
	EXPECT_TRUE(peer_allowed(0, {0}, options, kSelf)) << "root";
	EXPECT_TRUE(peer_allowed(kSelf, {kSelf}, options, kSelf)) << "the daemon's own user";
}
