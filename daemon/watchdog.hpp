#pragma once
// When the daemon tells systemd's watchdog it is alive (WATCHDOG=1), as a pure rule so it can be tested on
// counters alone. The watchdog is there to restart a daemon whose pipeline hangs; it must not restart one
// whose camera is away (the source reconnects on its own, clients stay connected).
#include <cstdint>

namespace stereod::daemon {

struct WatchdogSample {
	uint64_t captured = 0;	     ///< frames the capture thread took in so far
	uint64_t published = 0;	     ///< frames published so far
	int64_t capture_turn_ns = 0; ///< CLOCK_MONOTONIC of the capture loop's last turn
};

/// Alive when the capture loop is still turning (within `stall_limit_ns` of `now_ns`) and frames get through:
/// some were published since `before`, or none came in (a source that is waiting or reconnecting is not the
/// pipeline's fault). Frames coming in while none are published is a hung stage; a capture loop that stopped
/// turning is a hung driver call. Either way the pings stop and systemd restarts the service.
constexpr bool pipeline_alive(const WatchdogSample &before, const WatchdogSample &now, int64_t now_ns,
			      int64_t stall_limit_ns) noexcept
{
	if (now_ns - now.capture_turn_ns > stall_limit_ns)
		return false;
	return now.published > before.published || now.captured == before.captured;
}

} // namespace stereod::daemon
