#pragma once
// The results socket: a Unix-domain stream socket that streams newline-delimited JSON to any number of
// clients. publish() never waits for a client: each client has a bounded queue, and a client too slow to
// keep up loses its oldest messages (counted, and told with a `lag` message). A client that sends more
// than it may is dropped and counted.
#include <atomic>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <sys/types.h>

#include <sys/un.h>

namespace stereod::daemon {

/// The address of a Unix socket file, for bind or connect; throws std::runtime_error naming the path when it
/// is empty or longer than sockaddr_un holds (instead of silently cutting it).
sockaddr_un unix_socket_address(const std::string &path);

struct SocketServerOptions {
	std::string path;
	int mode = 0660;
	size_t client_queue = 256;
	size_t client_max_input = 4096;
	size_t max_clients = 64;		     ///< more are refused with an error line and counted
	size_t client_queue_bytes = 8 * 1024 * 1024; ///< a client's queue is also bounded in bytes
	/// Who may read (SO_PEERCRED / SO_PEERGROUPS): a client whose uid is listed, or whose primary or
	/// supplementary groups include a listed gid. Both empty: anyone the socket file's mode lets connect.
	/// Root and the daemon's own user are always let in.
	std::vector<uid_t> allow_uids{};
	std::vector<gid_t> allow_gids{};
	/// Group owning the socket file (the daemon must belong to it); -1: the daemon's own.
	gid_t socket_gid = static_cast<gid_t>(-1);
	/// Sent first to every client (one line, without its newline); set_greeting() changes it later.
	std::string greeting{};
};

/// Whether a peer may read: the access rule of SocketServerOptions::allow_uids / allow_gids, pure.
bool peer_allowed(uid_t uid, const std::vector<gid_t> &groups, const SocketServerOptions &options, uid_t self);

struct SocketServerStats {
	size_t clients = 0;
	uint64_t accepted = 0;
	uint64_t messages_dropped = 0; ///< messages discarded from slow clients' queues
	uint64_t clients_dropped = 0;  ///< clients disconnected for misbehaving
	uint64_t clients_closed = 0;   ///< clients that hung up
	uint64_t clients_refused = 0;  ///< connections refused: client limit reached or out of file descriptors
	uint64_t clients_denied = 0;   ///< connections refused: the peer's user and groups are not allowed
};

class SocketServer
{
public:
	/// Binds and listens; throws std::runtime_error naming the path when that fails (e.g. another
	/// stereod already listens there). A stale socket file from a dead daemon is replaced.
	explicit SocketServer(SocketServerOptions options);
	~SocketServer();
	SocketServer(const SocketServer &) = delete;
	SocketServer &operator=(const SocketServer &) = delete;

	/// Sent first to every new client.
	void set_greeting(std::string line);
	/// New limits, access lists, socket mode and group (a reload); the path stays. Clients stay connected
	/// (access lists apply to new connections); a limit lowered below what a client holds applies from its
	/// next message.
	void set_limits(const SocketServerOptions &options);
	/// Queues one line (without its newline) for every connected client. Thread-safe, never blocks on I/O.
	void publish(std::string line);
	[[nodiscard]] SocketServerStats stats() const;

private:
	struct Client {
		std::deque<std::shared_ptr<const std::string>> queue;
		size_t queued_bytes = 0; ///< sum of the queued messages' sizes
		size_t offset = 0;	 ///< bytes of queue.front() already sent
		uint64_t dropped_total = 0;
		uint64_t dropped_unreported = 0;
		std::string lag;       ///< a lag notice being sent
		size_t lag_offset = 0; ///< bytes of `lag` already sent
		size_t input_bytes = 0;
		bool writable_wait = false; ///< registered for EPOLLOUT
		bool input_closed = false;  ///< the client shut down its sending side
	};

	void run();
	void accept_clients();
	/// Accepts one pending connection only to tell it why it is refused, then closes it.
	void refuse(int fd, const char *why);
	/// Sends `why` as an `error` line (without waiting) and closes the connection.
	static void tell_and_close(int fd, const std::string &why);
	/// True when the peer on `fd` may read (options_.allow_uids / allow_gids); otherwise tells it, closes it,
	/// counts it and returns false.
	bool admit(int fd);
	/// Called with mutex_ held. Returns false when the client was closed (and erased).
	bool flush(int fd, Client &client);
	void drop_oldest(Client &client);
	void close_client(int fd, bool misbehaved);
	void update_interest(int fd, Client &client, bool force);

	SocketServerOptions options_;
	int listen_fd_ = -1;
	int epoll_fd_ = -1;
	int wake_fd_ = -1;
	int reserve_fd_ = -1; ///< held open so that a refusal can still accept when descriptors run out
	int64_t next_refusal_log_ns_ = 0;
	int64_t listen_paused_until_ns_ = 0; ///< out of descriptors: not watching for connections until then
	uint64_t refusals_unlogged_ = 0;
	uint64_t denials_unlogged_ = 0;
	int64_t next_denial_log_ns_ = 0;
	std::atomic<bool> stop_{false};
	mutable std::mutex mutex_;
	std::map<int, Client> clients_;
	std::shared_ptr<const std::string> greeting_;
	SocketServerStats stats_;
	std::thread thread_;
};

} // namespace stereod::daemon
