#pragma once
// Live recording beside the stream (`[record] path`, issue 17). The pipeline's workers hand each raw frame to
// offer(), which copies it into one of a few preallocated slots and returns at once; a thread of its own writes
// the slots to a recording (.srec, or MCAP with the results beside: drivers/replay/mcap_recording.hpp) in
// sequence order. A disk slower than the camera costs
// recorded frames (counted as `dropped`), never the pipeline's. A write that fails (a full disk, an I/O
// error) ends the recording: the error is kept for `status` and logged, the file keeps every complete record
// (each is one write() with its own CRC), and the stream goes on.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/frame.hpp"
#include "core/protocol.hpp"
#include "drivers/replay/recording.hpp"

namespace stereod::daemon {

class LiveRecorder
{
public:
	/// Creates (truncates) `path` and writes the header; throws std::runtime_error naming the path when it
	/// cannot. `slots` frames of the header's geometry are allocated here, once.
	LiveRecorder(const std::string &path, const drivers::RecordingHeader &header, size_t slots, bool sync,
		     const drivers::RecorderOptions &options = {});
	/// Writes what is queued, then stops.
	~LiveRecorder();
	LiveRecorder(const LiveRecorder &) = delete;
	LiveRecorder &operator=(const LiveRecorder &) = delete;

	/// Any thread: queue a copy of `frame` (its buffers are the caller's again on return). Never blocks on the
	/// disk: with every slot waiting to be written the frame is counted as dropped.
	void offer(const StereoFrame &frame);
	/// The publisher: queue a processed result (a protocol `frame` message) where the format records results
	/// (MCAP). Bounded like the frames: past the bound, results are dropped (and counted with the frames).
	void offer_result(int64_t t_capture_ns, std::string message);
	[[nodiscard]] bool records_results() const { return records_results_; }
	[[nodiscard]] protocol::StatusReport::Recording stats() const;

private:
	void write_loop();

	std::string path_;
	std::unique_ptr<drivers::FrameRecorder> writer_;
	bool records_results_ = false;
	bool sync_;
	std::vector<StereoFrame> slots_;
	mutable std::mutex mutex_;
	std::condition_variable queued_cv_;
	std::vector<size_t> free_;			       ///< slot indices ready for a copy
	std::vector<size_t> queued_;			       ///< slot indices waiting to be written
	std::vector<std::pair<int64_t, std::string>> results_; ///< results waiting to be written
	std::vector<std::pair<int64_t, std::string>> writing_; ///< the writer's batch (swapped, so reused)
	bool stopping_ = false;
	bool failed_ = false;
	std::string error_;
	uint64_t frames_ = 0;
	uint64_t bytes_ = 0;
	std::atomic<uint64_t> dropped_{0};
	std::thread thread_;
};

} // namespace stereod::daemon
