// notify_recv: stands in for systemd's side of sd_notify, so a test can see what the daemon tells systemd
// without booting systemd. It binds an AF_UNIX datagram socket with SO_PASSCRED (so every message carries
// its sender's pid, as systemd checks), runs the command with NOTIFY_SOCKET set (and WATCHDOG_USEC /
// WATCHDOG_PID, as systemd sets them for WatchdogSec=), prints every message with its time and sender pid,
// sends SIGTERM after --term-after seconds and SIGKILL after --kill-after, and exits with the command's code.
//   notify_recv [--watchdog-usec N] [--term-after S] [--kill-after S] -- COMMAND ARGS...
// Output lines: "<seconds since start> <pid> <field>|<field>..." and finally "exit <code>" or "signal <n>".
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

namespace {

double seconds_since(std::chrono::steady_clock::time_point start)
{
	return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// Prints every datagram waiting on `fd`.
void drain(int fd, std::chrono::steady_clock::time_point start)
{
	for (;;) {
		char data[4096];
		alignas(cmsghdr) char control[CMSG_SPACE(sizeof(ucred))];
		iovec io{data, sizeof(data) - 1};
		msghdr msg{};
		msg.msg_iov = &io;
		msg.msg_iovlen = 1;
		msg.msg_control = control;
		msg.msg_controllen = sizeof(control);
		const ssize_t n = recvmsg(fd, &msg, MSG_DONTWAIT);
		if (n < 0)
			return;
		data[n] = '\0';
		pid_t pid = 0;
		for (cmsghdr *c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c))
			if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_CREDENTIALS) {
				ucred cred{};
				std::memcpy(&cred, CMSG_DATA(c), sizeof(cred));
				pid = cred.pid;
			}
		std::string text(data, static_cast<size_t>(n));
		while (!text.empty() && text.back() == '\n')
			text.pop_back();
		for (char &ch : text)
			if (ch == '\n')
				ch = '|';
		std::printf("%.3f %d %s\n", seconds_since(start), static_cast<int>(pid), text.c_str());
		std::fflush(stdout);
	}
}

} // namespace

int main(int argc, char **argv)
{
	long watchdog_usec = 0;
	double term_after = 0, kill_after = 0;
	int i = 1;
	for (; i < argc && std::strcmp(argv[i], "--") != 0; ++i) {
		const std::string arg = argv[i];
		if (i + 1 >= argc) {
			std::fprintf(stderr, "notify_recv: %s needs a value\n", arg.c_str());
			return 2;
		}
		if (arg == "--watchdog-usec")
			watchdog_usec = std::atol(argv[++i]);
		else if (arg == "--term-after")
			term_after = std::atof(argv[++i]);
		else if (arg == "--kill-after")
			kill_after = std::atof(argv[++i]);
		else {
			std::fprintf(stderr, "notify_recv: unknown option %s\n", arg.c_str());
			return 2;
		}
	}
	if (i + 1 >= argc) {
		std::fprintf(stderr,
			     "usage: notify_recv [--watchdog-usec N] [--term-after S] [--kill-after S] -- CMD...\n");
		return 2;
	}
	char dir_template[] = "/tmp/notify_recv.XXXXXX";
	if (mkdtemp(dir_template) == nullptr) {
		std::perror("notify_recv: mkdtemp");
		return 2;
	}
	const std::string path = std::string(dir_template) + "/notify.sock";
	const int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
	sockaddr_un addr{};
	addr.sun_family = AF_UNIX;
	std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
	const int on = 1;
	if (fd < 0 || bind(fd, reinterpret_cast<sockaddr *>(&addr), sizeof(addr)) != 0 ||
	    setsockopt(fd, SOL_SOCKET, SO_PASSCRED, &on, sizeof(on)) != 0) {
		std::perror("notify_recv: socket");
		return 2;
	}
	const auto start = std::chrono::steady_clock::now();
	const pid_t child = fork();
	if (child == 0) {
		setenv("NOTIFY_SOCKET", path.c_str(), 1);
		if (watchdog_usec > 0) {
			setenv("WATCHDOG_USEC", std::to_string(watchdog_usec).c_str(), 1);
			setenv("WATCHDOG_PID", std::to_string(getpid()).c_str(), 1);
		}
		execvp(argv[i + 1], argv + i + 1);
		std::perror("notify_recv: exec");
		_exit(127);
	}
	std::printf("0.000 %d started\n", static_cast<int>(child));
	std::fflush(stdout);
	bool termed = false, killed = false;
	int status = 0;
	for (;;) {
		pollfd p{fd, POLLIN, 0};
		poll(&p, 1, 20);
		drain(fd, start);
		const double t = seconds_since(start);
		if (term_after > 0 && !termed && t >= term_after) {
			kill(child, SIGTERM);
			termed = true;
			std::printf("%.3f - SIGTERM sent\n", t);
		}
		if (kill_after > 0 && !killed && t >= kill_after) {
			kill(child, SIGKILL);
			killed = true;
			std::printf("%.3f - SIGKILL sent\n", t);
		}
		if (waitpid(child, &status, WNOHANG) == child)
			break;
	}
	drain(fd, start); // what the child sent just before it exited
	unlink(path.c_str());
	rmdir(dir_template);
	if (WIFEXITED(status)) {
		std::printf("exit %d\n", WEXITSTATUS(status));
		return WEXITSTATUS(status);
	}
	std::printf("signal %d\n", WTERMSIG(status));
	return 128 + WTERMSIG(status);
}
