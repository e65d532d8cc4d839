#pragma once
// The processing pipeline: capture thread -> lock-free ring -> dispatcher -> worker pool -> in-order
// publisher -> sink.
//
//   capture     takes a free pool frame, lets the source fill it, pushes its index into the ring
//               (drop-oldest for live sources, block for offline); counts every frame lost and why.
//   dispatcher  pops the ring in order and hands each frame to the workers with a future of the previous
//               frame's features, so frame n's classification can pair with n-1 while extraction of
//               several frames runs in parallel.
//   workers     run the stages (pure functions) and give the frame back to the pool.
//   publisher   re-orders results by dispatch order and hands them to the sink one by one.
#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <latch>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/frame_pool.hpp"
#include "core/geometry/rectify.hpp"
#include "core/latency.hpp"
#include "core/protocol.hpp"
#include "core/result.hpp"
#include "core/spsc_ring.hpp"
#include "core/vision/motion_stages.hpp"
#include "drivers/source.hpp"

namespace stereod::daemon {

struct PipelineOptions {
	size_t workers = 2;
	size_t ring_capacity = 8;
	OverflowPolicy overflow = OverflowPolicy::DropOldest;
	int worker_nice = 0;			///< workers run this much nicer than capture (0 = same priority)
	int64_t drain_limit_ns = 1'000'000'000; ///< live sources: how long a stop may spend on the backlog
	/// Each worker runs the vision stages on two made-up frames before capture starts, so the first camera
	/// frames do not pay for the workers' first allocations (docs/geometry.md, Cost).
	bool warm_up = true;
	vision::MotionParams motion;
	/// From a calibration file: both eyes are rectified before any vision stage (motion.rig is then its rig).
	std::shared_ptr<const geometry::Rectification> rectification;
};

struct PipelineStats {
	std::string source_state; ///< "starting", "streaming", "reconnecting", "finished", "stopped"
	uint64_t frames_captured = 0;
	uint64_t frames_published = 0;
	uint64_t ring_evicted = 0;	///< dropped by drop-oldest
	uint64_t pool_exhausted = 0;	///< grabbed into the spare frame and discarded: no pool frame was free
	uint64_t source_gaps = 0;	///< frames the source's own counter says never reached us
	uint64_t corrupt = 0;		///< frames marked corrupt by the source
	uint64_t processing_errors = 0; ///< frames a stage threw on
	uint64_t reconnects = 0;
	uint64_t dropped_at_stop = 0; ///< live backlog left unprocessed when the drain time ran out
	/// CLOCK_MONOTONIC at which the first and the last captured frame were complete on the host (0: none
	/// yet): a reload that rebuilds the pipeline measures the stream's pause from them.
	int64_t first_capture_host_ns = 0;
	int64_t last_capture_host_ns = 0;
	int64_t capture_turn_ns = 0; ///< CLOCK_MONOTONIC of the capture loop's last turn (daemon/watchdog.hpp)
	protocol::LatencySummary capture_to_publish;
	std::optional<protocol::StatusReport::StereoHealth> stereo; ///< stereo sources: calibration health
};

class Pipeline
{
public:
	/// Called on the publisher thread, in dispatch order; sets nothing itself but may stamp t_publish_ns.
	using Sink = std::function<void(FrameResult &)>;
	/// Called on a worker thread with each frame before it goes back to the pool (e.g. to save the truth).
	using FrameObserver = std::function<void(const StereoFrame &)>;

	Pipeline(std::unique_ptr<drivers::FrameSource> source, PipelineOptions options, Sink sink);
	~Pipeline();
	Pipeline(const Pipeline &) = delete;
	Pipeline &operator=(const Pipeline &) = delete;

	void set_frame_observer(FrameObserver observer) { observer_ = std::move(observer); }
	/// Starts the threads; returns once the workers are warm (PipelineOptions::warm_up) and capture runs.
	void start();
	/// Stops capture; frames already captured are still processed and published (drain).
	void request_stop();
	/// Waits until every captured frame has been published (after the source ended or request_stop()).
	void wait();
	[[nodiscard]] bool finished() const { return finished_.load(); }
	[[nodiscard]] PipelineStats stats() const;
	[[nodiscard]] const drivers::SourceInfo &source_info() const { return source_->info(); }
	[[nodiscard]] std::vector<std::string> source_report() const { return source_->report(); }
	[[nodiscard]] drivers::SourceCounters source_counters() const { return source_->counters(); }

private:
	using FeaturesPtr = std::shared_ptr<const vision::FrameFeatures>;
	using TracksPtr = std::shared_ptr<const vision::TrackSet>;

	struct Job {
		uint64_t order = 0;
		FrameHandle frame;
		std::shared_future<FeaturesPtr> previous;      ///< invalid for the first frame
		std::promise<FeaturesPtr> features;	       ///< fulfilled as soon as this frame's features exist
		std::shared_future<TracksPtr> previous_tracks; ///< the previous frame's motion memory
		std::promise<TracksPtr> tracks;		       ///< fulfilled once this frame is classified
		bool provides_features = true;		       ///< false for corrupt frames (they pass the previous on)
	};

	void capture_loop();
	void dispatch_loop();
	/// `warm_frames`: run the stages on these first (the warm-up), or null.
	void worker_loop(const std::array<StereoFrame, 2> *warm_frames);
	void warm_up(const std::array<StereoFrame, 2> &frames, vision::StageWorkspace &workspace);
	void publish_loop();
	void process(Job &job, vision::StageWorkspace &workspace);
	void set_state(const char *state);

	std::unique_ptr<drivers::FrameSource> source_;
	PipelineOptions options_;
	Sink sink_;
	FrameObserver observer_;
	std::string source_name_;

	FramePool pool_;
	SpscRing<uint32_t> ring_;
	StereoFrame spare_; ///< grabbed into when the pool is exhausted, so a live device is still drained

	std::mutex jobs_mutex_;
	std::condition_variable jobs_changed_;
	std::deque<std::unique_ptr<Job>> jobs_;
	size_t jobs_capacity_;
	bool jobs_closed_ = false;

	std::mutex results_mutex_;
	std::condition_variable results_changed_;
	std::map<uint64_t, FrameResult> results_;
	uint64_t dispatched_ = 0;
	uint64_t published_upto_ = 0; ///< results [0, published_upto_) have left through the sink
	size_t max_in_flight_;
	bool dispatch_done_ = false;

	std::atomic<bool> stop_{false};
	std::atomic<bool> finished_{false};
	std::atomic<uint64_t> captured_{0}, published_{0}, pool_exhausted_{0}, source_gaps_{0}, corrupt_{0},
		processing_errors_{0}, reconnects_{0}, dropped_at_stop_{0};
	std::atomic<int64_t> first_capture_host_ns_{0}, last_capture_host_ns_{0};
	std::atomic<int64_t> stop_deadline_ns_{0};
	std::atomic<int64_t> capture_turn_ns_{0}; ///< the capture loop's last turn (for the watchdog)
	mutable std::mutex state_mutex_;
	std::string state_ = "starting";
	LatencyWindow latency_{2048};
	vision::CalibrationHealth calibration_health_; ///< under state_mutex_

	std::latch workers_warm_; ///< counted down by each worker once warm; capture waits for it

	std::thread capture_thread_, dispatch_thread_, publish_thread_;
	std::vector<std::thread> workers_;
};

} // namespace stereod::daemon
