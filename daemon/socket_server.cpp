#include "daemon/socket_server.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <stdexcept>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include "core/clock.hpp"
#include "core/protocol.hpp"

namespace stereod::daemon {
namespace {

/// True when something accepts connections at `path` (so it is not ours to remove).
bool someone_listens(const std::string &path)
{
	const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0)
		return false;
	const sockaddr_un addr = unix_socket_address(path);
	const bool listening = ::connect(fd, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)) == 0;
	::close(fd);
	return listening;
}

} // namespace

bool peer_allowed(uid_t uid, const std::vector<gid_t> &groups, const SocketServerOptions &options, uid_t self)
{
	if (options.allow_uids.empty() && options.allow_gids.empty())
		return true;
	if (uid == 0 || uid == self)
		return true;
	if (std::find(options.allow_uids.begin(), options.allow_uids.end(), uid) != options.allow_uids.end())
		return true;
	return std::any_of(groups.begin(), groups.end(), [&](gid_t g) {
		return std::find(options.allow_gids.begin(), options.allow_gids.end(), g) != options.allow_gids.end();
	});
}

sockaddr_un unix_socket_address(const std::string &path)
{
	sockaddr_un addr{};
	addr.sun_family = AF_UNIX;
	if (path.empty() || path.size() >= sizeof(addr.sun_path))
		throw std::runtime_error("socket path '" + path + "' is empty or longer than " +
					 std::to_string(sizeof(addr.sun_path) - 1) + " bytes");
	std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
	return addr;
}

SocketServer::SocketServer(SocketServerOptions options) : options_(std::move(options))
{
	const sockaddr_un addr = unix_socket_address(options_.path);
	std::error_code ec;
	const auto parent = std::filesystem::path(options_.path).parent_path();
	if (!parent.empty())
		std::filesystem::create_directories(parent, ec);
	struct stat st {
	};
	if (::lstat(options_.path.c_str(), &st) == 0) {
		if (!S_ISSOCK(st.st_mode))
			throw std::runtime_error(options_.path +
						 ": exists and is not a socket; refusing to replace it");
		if (someone_listens(options_.path))
			throw std::runtime_error(options_.path + ": another process is already listening there");
		::unlink(options_.path.c_str()); // stale, left by a daemon that died
	}
	listen_fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	if (listen_fd_ < 0)
		throw std::runtime_error(std::string("socket(): ") + std::strerror(errno));
	if (::bind(listen_fd_, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)) != 0) {
		const int err = errno;
		::close(listen_fd_);
		throw std::runtime_error(options_.path + ": cannot bind: " + std::strerror(err));
	}
	// chmod after bind: the mode must not depend on the process umask.
	::chmod(options_.path.c_str(), static_cast<mode_t>(options_.mode));
	if (options_.socket_gid != static_cast<gid_t>(-1) &&
	    ::chown(options_.path.c_str(), static_cast<uid_t>(-1), options_.socket_gid) != 0) {
		const int err = errno;
		::close(listen_fd_);
		::unlink(options_.path.c_str());
		throw std::runtime_error(options_.path + ": cannot give the socket to group " +
					 std::to_string(options_.socket_gid) +
					 " (output.socket_group): " + std::strerror(err));
	}
	if (::listen(listen_fd_, 64) != 0) {
		const int err = errno;
		::close(listen_fd_);
		::unlink(options_.path.c_str());
		throw std::runtime_error(options_.path + ": cannot listen: " + std::strerror(err));
	}
	epoll_fd_ = ::epoll_create1(EPOLL_CLOEXEC);
	wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	epoll_event ev{};
	ev.events = EPOLLIN;
	ev.data.fd = listen_fd_;
	::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, listen_fd_, &ev);
	ev.data.fd = wake_fd_;
	::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, wake_fd_, &ev);
	reserve_fd_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
	if (!options_.greeting.empty()) // before the first client can be accepted
		greeting_ = std::make_shared<const std::string>(options_.greeting + "\n");
	thread_ = std::thread([this] { run(); });
}

SocketServer::~SocketServer()
{
	stop_.store(true);
	const uint64_t one = 1;
	(void)!::write(wake_fd_, &one, sizeof(one));
	if (thread_.joinable())
		thread_.join();
	// Best effort: hand each client what is still queued before closing. flush() closes and erases a client
	// whose send fails, so take each client out of the map before touching it: an iterator into a map that
	// flush() shrinks is what crashed here under connection churn.
	while (!clients_.empty()) {
		const int fd = clients_.begin()->first;
		if (flush(fd, clients_.begin()->second)) {
			::close(fd);
			clients_.erase(fd);
		}
	}
	::close(listen_fd_);
	::unlink(options_.path.c_str());
	::close(epoll_fd_);
	::close(wake_fd_);
	if (reserve_fd_ >= 0)
		::close(reserve_fd_);
}

void SocketServer::set_limits(const SocketServerOptions &options)
{
	std::lock_guard lock(mutex_);
	options_.client_queue = options.client_queue;
	options_.client_queue_bytes = options.client_queue_bytes;
	options_.client_max_input = options.client_max_input;
	options_.max_clients = options.max_clients;
	options_.allow_uids = options.allow_uids;
	options_.allow_gids = options.allow_gids;
	if (options.socket_gid != options_.socket_gid && options.socket_gid != static_cast<gid_t>(-1)) {
		options_.socket_gid = options.socket_gid;
		if (::chown(options_.path.c_str(), static_cast<uid_t>(-1), options_.socket_gid) != 0)
			spdlog::error("socket: cannot give {} to group {} (output.socket_group): {}", options_.path,
				      options_.socket_gid, std::strerror(errno));
	}
	if (options.mode != options_.mode) {
		options_.mode = options.mode;
		::chmod(options_.path.c_str(), static_cast<mode_t>(options_.mode));
	}
}

void SocketServer::set_greeting(std::string line)
{
	line.push_back('\n');
	std::lock_guard lock(mutex_);
	greeting_ = std::make_shared<const std::string>(std::move(line));
}

void SocketServer::drop_oldest(Client &client)
{
	// Drop the oldest message not yet begun: a half-sent line must be finished.
	const auto victim = client.offset > 0 ? client.queue.begin() + 1 : client.queue.begin();
	if (victim == client.queue.end())
		return;
	client.queued_bytes -= (*victim)->size();
	client.queue.erase(victim);
	++client.dropped_total;
	++client.dropped_unreported;
	++stats_.messages_dropped;
}

void SocketServer::publish(std::string line)
{
	line.push_back('\n');
	auto message = std::make_shared<const std::string>(std::move(line));
	{
		std::lock_guard lock(mutex_);
		for (auto &[fd, client] : clients_) {
			// Bounded by count and by bytes: a client that never reads costs at most client_queue_bytes.
			while (!client.queue.empty() &&
			       (client.queue.size() >= options_.client_queue ||
				client.queued_bytes + message->size() > options_.client_queue_bytes)) {
				const size_t before = client.queue.size();
				drop_oldest(client);
				if (client.queue.size() == before)
					break; // only the half-sent message is left
			}
			client.queue.push_back(message);
			client.queued_bytes += message->size();
		}
	}
	const uint64_t one = 1;
	(void)!::write(wake_fd_, &one, sizeof(one));
}

SocketServerStats SocketServer::stats() const
{
	std::lock_guard lock(mutex_);
	SocketServerStats s = stats_;
	s.clients = clients_.size();
	return s;
}

void SocketServer::run()
{
	std::array<epoll_event, 32> events{};
	while (!stop_.load()) {
		const int n = ::epoll_wait(epoll_fd_, events.data(), static_cast<int>(events.size()),
					   listen_paused_until_ns_ != 0 ? 50 : 500);
		if (n < 0 && errno != EINTR) {
			spdlog::error("socket server: epoll_wait: {}", std::strerror(errno));
			break;
		}
		std::lock_guard lock(mutex_);
		if (listen_paused_until_ns_ != 0 && monotonic_ns() >= listen_paused_until_ns_) {
			listen_paused_until_ns_ = 0;
			epoll_event ev{};
			ev.events = EPOLLIN;
			ev.data.fd = listen_fd_;
			::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, listen_fd_, &ev);
			if (reserve_fd_ < 0)
				reserve_fd_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
		}
		for (int i = 0; i < n; ++i) {
			const int fd = events[static_cast<size_t>(i)].data.fd;
			const uint32_t what = events[static_cast<size_t>(i)].events;
			if (fd == listen_fd_) {
				accept_clients();
			} else if (fd == wake_fd_) {
				uint64_t count = 0;
				(void)!::read(wake_fd_, &count, sizeof(count));
			} else if (auto it = clients_.find(fd); it != clients_.end()) {
				if (what & EPOLLIN) {
					char sink[1024];
					ssize_t got = 0;
					bool closed = false;
					while ((got = ::recv(fd, sink, sizeof(sink), MSG_DONTWAIT)) > 0)
						it->second.input_bytes += static_cast<size_t>(got);
					if (got == 0)
						closed = true;
					if (it->second.input_bytes > options_.client_max_input) {
						spdlog::warn("socket: client {} sent {} bytes (limit {}); dropped", fd,
							     it->second.input_bytes, options_.client_max_input);
						close_client(fd, true);
						continue;
					}
					if (closed) {
						// The client shut down its sending side (e.g. socat with stdin at
						// EOF); it may still read, so keep it and stop listening for input.
						it->second.input_closed = true;
						update_interest(fd, it->second, true);
					}
				}
				if (what & (EPOLLHUP | EPOLLERR)) {
					close_client(fd, false);
					continue;
				}
			}
		}
		// Write whatever is queued; clients that would block wait for EPOLLOUT.
		for (auto it = clients_.begin(); it != clients_.end();) {
			const int fd = it->first;
			++it; // flush may close (and erase) this client
			if (auto c = clients_.find(fd); c != clients_.end())
				flush(fd, c->second);
		}
	}
}

void SocketServer::accept_clients()
{
	for (;;) {
		const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd < 0) {
			if (errno != EMFILE && errno != ENFILE)
				return; // EAGAIN: nothing more pending
			// Out of descriptors (accept fails so even with nothing pending). A pending connection would
			// keep the listening socket readable and this thread spinning: free the reserve, accept it to
			// refuse it, take the reserve back.
			int refused = -1;
			if (reserve_fd_ >= 0) {
				::close(reserve_fd_);
				refused = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
				if (refused >= 0)
					refuse(refused, "the daemon is out of file descriptors");
				reserve_fd_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
			}
			if (refused < 0 || reserve_fd_ < 0) {
				// Nothing was pending, or the reserve is gone: stop watching for connections for a
				// moment rather than spin on a socket we cannot serve.
				::epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, listen_fd_, nullptr);
				listen_paused_until_ns_ = monotonic_ns() + 100'000'000;
				return;
			}
			continue;
		}
		if (!admit(fd))
			continue;
		if (clients_.size() >= options_.max_clients) {
			refuse(fd, "too many clients");
			continue;
		}
		Client &client = clients_[fd];
		if (greeting_) {
			client.queue.push_back(greeting_);
			client.queued_bytes += greeting_->size();
		}
		epoll_event ev{};
		ev.events = EPOLLIN | EPOLLRDHUP;
		ev.data.fd = fd;
		::epoll_ctl(epoll_fd_, EPOLL_CTL_ADD, fd, &ev);
		++stats_.accepted;
		// Per-client lines at debug only: connection churn must not flood the journal. The status
		// message and the periodic status log carry the counts.
		spdlog::debug("socket: client {} connected ({} now)", fd, clients_.size());
	}
}

void SocketServer::tell_and_close(int fd, const std::string &why)
{
	const std::string line = protocol::error_message(monotonic_ns(), why) + "\n";
	(void)!::send(fd, line.data(), line.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
	::close(fd);
}

void SocketServer::refuse(int fd, const char *why)
{
	tell_and_close(fd, why);
	++stats_.clients_refused;
	++refusals_unlogged_;
	const int64_t now = monotonic_ns();
	if (now >= next_refusal_log_ns_) { // at most one line every 10 s, however many are refused
		spdlog::warn("socket: refused {} client(s): {} (limit {} clients)", refusals_unlogged_, why,
			     options_.max_clients);
		refusals_unlogged_ = 0;
		next_refusal_log_ns_ = now + 10'000'000'000;
	}
}

bool SocketServer::admit(int fd)
{
	if (options_.allow_uids.empty() && options_.allow_gids.empty())
		return true;
	ucred cred{};
	socklen_t len = sizeof(cred);
	std::vector<gid_t> groups;
	if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) == 0) {
		groups.push_back(cred.gid);
		// The groups the peer process really holds (a client given groups at run time, e.g. by systemd's
		// SupplementaryGroups=, is not in /etc/group).
		gid_t supplementary[256];
		socklen_t bytes = sizeof(supplementary);
		if (::getsockopt(fd, SOL_SOCKET, SO_PEERGROUPS, supplementary, &bytes) == 0)
			groups.insert(groups.end(), supplementary, supplementary + bytes / sizeof(gid_t));
		if (peer_allowed(cred.uid, groups, options_, ::geteuid()))
			return true;
	} else {
		cred.uid = static_cast<uid_t>(-1); // unknown peer: refused
	}
	tell_and_close(fd, "not allowed: uid " + std::to_string(cred.uid) +
				   " is not in output.allow_users or a group of output.allow_groups");
	++stats_.clients_denied;
	++denials_unlogged_;
	const int64_t now = monotonic_ns();
	if (now >= next_denial_log_ns_) { // at most one line every 10 s, however many knock
		spdlog::warn("socket: refused {} client(s) not allowed to read (last: uid {}, pid {})",
			     denials_unlogged_, cred.uid, cred.pid);
		denials_unlogged_ = 0;
		next_denial_log_ns_ = now + 10'000'000'000;
	}
	return false;
}

bool SocketServer::flush(int fd, Client &client)
{
	auto send_some = [&](const std::string &data, size_t &offset) {
		const ssize_t sent =
			::send(fd, data.data() + offset, data.size() - offset, MSG_DONTWAIT | MSG_NOSIGNAL);
		if (sent < 0)
			return errno == EAGAIN || errno == EWOULDBLOCK ? 0 : -1;
		offset += static_cast<size_t>(sent);
		return offset == data.size() ? 1 : 0;
	};
	for (;;) {
		// A lag notice goes out between two messages, never inside one; it lives outside the queue so
		// that dropping the oldest queued message can never drop the notice.
		if (client.lag.empty() && client.offset == 0 && client.dropped_unreported > 0) {
			client.lag =
				protocol::lag_message(monotonic_ns(), client.dropped_total, client.dropped_unreported) +
				"\n";
			client.lag_offset = 0;
			client.dropped_unreported = 0;
		}
		int done = 0;
		if (!client.lag.empty()) {
			done = send_some(client.lag, client.lag_offset);
			if (done == 1)
				client.lag.clear();
		} else if (!client.queue.empty()) {
			done = send_some(*client.queue.front(), client.offset);
			if (done == 1) {
				client.queued_bytes -= client.queue.front()->size();
				client.queue.pop_front();
				client.offset = 0;
			}
		} else {
			break;
		}
		if (done < 0) {
			close_client(fd, false);
			return false;
		}
		if (done == 0)
			break; // the socket is full: wait for EPOLLOUT
	}
	update_interest(fd, client, false);
	return true;
}

void SocketServer::update_interest(int fd, Client &client, bool force)
{
	const bool want = !client.queue.empty() || !client.lag.empty();
	if (want == client.writable_wait && !force)
		return;
	epoll_event ev{};
	ev.events = (client.input_closed ? 0U : EPOLLIN | EPOLLRDHUP) | (want ? EPOLLOUT : 0U);
	ev.data.fd = fd;
	::epoll_ctl(epoll_fd_, EPOLL_CTL_MOD, fd, &ev);
	client.writable_wait = want;
}

void SocketServer::close_client(int fd, bool misbehaved)
{
	::epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, fd, nullptr);
	::close(fd);
	clients_.erase(fd);
	if (misbehaved)
		++stats_.clients_dropped;
	else
		++stats_.clients_closed;
	if (misbehaved)
		spdlog::warn("socket: client {} dropped ({} left)", fd, clients_.size());
	else
		spdlog::debug("socket: client {} disconnected ({} left)", fd, clients_.size());
}

} // namespace stereod::daemon
