#include "daemon/pipeline.hpp"

#include <chrono>
#include <sys/resource.h>
#include <unistd.h>

#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>

#include "core/clock.hpp"
#include "core/stage_timer.hpp"

namespace stereod::daemon {

Pipeline::Pipeline(std::unique_ptr<drivers::FrameSource> source, PipelineOptions options, Sink sink)
	: source_(std::move(source)), options_(options), sink_(std::move(sink)), source_name_(source_->info().name),
	  // Enough frames for a full ring, a full job queue, one per worker and the one being captured.
	  pool_(options_.ring_capacity + 2 * options_.workers + options_.workers + 2, source_->info().geometry),
	  ring_(options_.ring_capacity, options_.overflow), jobs_capacity_(2 * options_.workers),
	  max_in_flight_(jobs_capacity_ + options_.workers + 1),
	  workers_warm_(static_cast<std::ptrdiff_t>(options_.workers))
{
	if (options_.workers == 0)
		throw std::invalid_argument("pipeline needs at least one worker");
	spare_.allocate(source_->info().geometry);
}

namespace {

/// Two frames of the source's geometry made up for the warm-up: smoothed noise (corners everywhere, as a
/// textured scene has), the right eye shifted as by a 12 px disparity, the second frame moved by 3 px as a
/// scene moves; depth 4 m. What they contain does not matter, only that every stage has work to do.
std::array<StereoFrame, 2> warm_up_frames(const FrameGeometry &geometry)
{
	std::array<StereoFrame, 2> frames;
	cv::Mat texture(geometry.height + 8, geometry.width + 16, cv_type(geometry.format));
	cv::randu(texture, cv::Scalar::all(0), cv::Scalar::all(255));
	cv::GaussianBlur(texture, texture, cv::Size(0, 0), 1.5);
	for (size_t i = 0; i < frames.size(); ++i) {
		StereoFrame &frame = frames[i];
		frame.allocate(geometry);
		const int shift = 3 * static_cast<int>(i);
		texture(cv::Rect(shift, shift, geometry.width, geometry.height)).copyTo(frame.left);
		if (!frame.right.empty())
			texture(cv::Rect(shift + 12, shift, geometry.width, geometry.height)).copyTo(frame.right);
		if (!frame.depth.empty())
			frame.depth.setTo(4.0F);
		if (!frame.truth.object_ids.empty())
			frame.truth.object_ids.setTo(0);
		frame.sequence = i;
		frame.device_ns = static_cast<int64_t>(i) * 33'000'000;
	}
	return frames;
}

} // namespace

Pipeline::~Pipeline()
{
	request_stop();
	wait();
}

void Pipeline::start()
{
	capture_turn_ns_.store(monotonic_ns());
	publish_thread_ = std::thread([this] { publish_loop(); });
	// Made once, read by every worker; they outlive the warm-up, which start() waits for.
	const int64_t warm_start_ns = monotonic_ns();
	const bool warm = options_.warm_up && options_.motion.enabled;
	const std::array<StereoFrame, 2> frames =
		warm ? warm_up_frames(source_->info().geometry) : std::array<StereoFrame, 2>{};
	for (size_t i = 0; i < options_.workers; ++i)
		workers_.emplace_back([this, warm_frames = warm ? &frames : nullptr] { worker_loop(warm_frames); });
	workers_warm_.wait(); // capture starts with every worker ready
	if (warm)
		spdlog::info("workers warmed up in {:.0f} ms",
			     static_cast<double>(monotonic_ns() - warm_start_ns) * 1e-6);
	dispatch_thread_ = std::thread([this] { dispatch_loop(); });
	capture_thread_ = std::thread([this] { capture_loop(); });
}

void Pipeline::request_stop()
{
	// The capture thread sees stop_, hands over the frame it holds and closes the ring itself, so a frame
	// already grabbed is never lost on the way out.
	stop_deadline_ns_.store(monotonic_ns() + options_.drain_limit_ns);
	stop_.store(true);
	pool_.wake_waiters();
}

void Pipeline::wait()
{
	for (std::thread *t : {&capture_thread_, &dispatch_thread_})
		if (t->joinable())
			t->join();
	for (auto &worker : workers_)
		if (worker.joinable())
			worker.join();
	if (publish_thread_.joinable())
		publish_thread_.join();
}

void Pipeline::set_state(const char *state)
{
	std::lock_guard lock(state_mutex_);
	state_ = state;
}

PipelineStats Pipeline::stats() const
{
	PipelineStats s;
	s.capture_turn_ns = capture_turn_ns_.load();
	{
		std::lock_guard lock(state_mutex_);
		s.source_state = state_;
		s.capture_to_publish = latency_.summary();
		if (calibration_health_.frames() > 0)
			s.stereo = protocol::StatusReport::StereoHealth{
				calibration_health_.frames(), calibration_health_.row_diff_px(),
				calibration_health_.outside_band_fraction(), calibration_health_.drifted()};
	}
	s.frames_captured = captured_.load();
	s.frames_published = published_.load();
	s.ring_evicted = ring_.counters().evicted;
	s.pool_exhausted = pool_exhausted_.load();
	s.source_gaps = source_gaps_.load();
	s.corrupt = corrupt_.load();
	s.processing_errors = processing_errors_.load();
	s.reconnects = reconnects_.load();
	s.dropped_at_stop = dropped_at_stop_.load();
	s.first_capture_host_ns = first_capture_host_ns_.load();
	s.last_capture_host_ns = last_capture_host_ns_.load();
	return s;
}

void Pipeline::capture_loop()
{
	const bool live = source_->info().live;
	bool have_last = false;
	uint64_t last_sequence = 0;
	set_state("streaming");
	auto backoff = std::chrono::milliseconds(100);
	while (!stop_.load()) {
		capture_turn_ns_.store(monotonic_ns());
		std::optional<FrameHandle> frame =
			live ? pool_.try_acquire() : pool_.acquire_waiting([this] { return stop_.load(); });
		if (!frame && !live)
			break; // stopping
		StereoFrame &target = frame ? **frame : spare_;
		drivers::GrabStatus status{};
		try {
			status = source_->grab(target);
		} catch (const std::exception &e) {
			spdlog::error("capture: {}: {}", source_name_, e.what());
			// A live device may come back; a file that fails to read will not, so its stream ends here.
			status = live ? drivers::GrabStatus::Lost : drivers::GrabStatus::EndOfStream;
		}
		if (status == drivers::GrabStatus::EndOfStream)
			break;
		if (status == drivers::GrabStatus::Timeout)
			continue;
		if (status == drivers::GrabStatus::Lost) {
			set_state("reconnecting");
			while (!stop_.load()) {
				capture_turn_ns_.store(monotonic_ns());
				std::this_thread::sleep_for(backoff);
				backoff = std::min(backoff * 2, std::chrono::milliseconds(2000));
				if (source_->reconnect()) {
					reconnects_.fetch_add(1);
					spdlog::info("capture: {} reconnected", source_name_);
					break;
				}
			}
			backoff = std::chrono::milliseconds(100);
			set_state("streaming");
			continue;
		}

		captured_.fetch_add(1);
		const int64_t host_ns = target.host_ns > 0 ? target.host_ns : monotonic_ns();
		if (first_capture_host_ns_.load(std::memory_order_relaxed) == 0)
			first_capture_host_ns_.store(host_ns);
		last_capture_host_ns_.store(host_ns);
		if (have_last && target.sequence > last_sequence + 1)
			source_gaps_.fetch_add(target.sequence - last_sequence - 1);
		have_last = true;
		last_sequence = target.sequence;
		if (target.status == FrameStatus::Corrupt)
			corrupt_.fetch_add(1);
		if (!frame) {
			pool_exhausted_.fetch_add(1);
			continue;
		}
		uint32_t evicted = 0;
		const uint32_t index = frame->release();
		const auto pushed = ring_.push(index, evicted);
		if (pushed == SpscRing<uint32_t>::PushResult::PushedEvicted) {
			pool_.adopt(evicted).reset(); // back to the pool; the ring counts it
		} else if (pushed == SpscRing<uint32_t>::PushResult::Closed) {
			pool_.adopt(index).reset();
			break;
		}
	}
	set_state(stop_.load() ? "stopped" : "finished");
	ring_.close();
}

void Pipeline::dispatch_loop()
{
	std::shared_future<FeaturesPtr> previous;
	std::shared_future<TracksPtr> previous_tracks;
	uint64_t order = 0;
	const bool live = source_->info().live;
	while (auto index = ring_.pop()) {
		// A live source's backlog is drained for a bounded time (drain_limit_ns) after a stop (a 1024-frame
		// ring once took 5.5 s); what is left then is given back unprocessed and counted. Offline, everything
		// is processed.
		if (live && stop_.load() && monotonic_ns() > stop_deadline_ns_.load()) {
			pool_.adopt(*index).reset();
			dropped_at_stop_.fetch_add(1);
			continue;
		}
		auto job = std::make_unique<Job>();
		job->order = order++;
		job->frame = pool_.adopt(*index);
		job->previous = previous;
		job->previous_tracks = previous_tracks;
		job->provides_features = job->frame->status != FrameStatus::Corrupt;
		if (job->provides_features) {
			previous = job->features.get_future().share();
			previous_tracks = job->tracks.get_future().share();
		}
		{
			// Bound the frames in flight, so a slow sink backs up into the ring (where the overflow
			// policy decides) instead of into an ever-growing pile of finished results.
			std::unique_lock lock(results_mutex_);
			results_changed_.wait(lock, [&] { return job->order < published_upto_ + max_in_flight_; });
		}
		std::unique_lock lock(jobs_mutex_);
		jobs_changed_.wait(lock, [this] { return jobs_.size() < jobs_capacity_; });
		jobs_.push_back(std::move(job));
		jobs_changed_.notify_all();
	}
	{
		std::lock_guard lock(jobs_mutex_);
		jobs_closed_ = true;
	}
	jobs_changed_.notify_all();
	{
		std::lock_guard lock(results_mutex_);
		dispatched_ = order;
		dispatch_done_ = true;
	}
	results_changed_.notify_all();
}

void Pipeline::warm_up(const std::array<StereoFrame, 2> &frames, vision::StageWorkspace &workspace)
{
	// A worker's first frames took up to 80-100 ms against 25 ms later (OpenCV's buffers, the thread's heap,
	// the code's pages), enough to set a 15 s run's p99; paid here instead, before capture starts.
	std::vector<StageTime> timing;
	std::array<vision::FrameFeatures, 2> features;
	for (size_t i = 0; i < frames.size(); ++i) {
		const StereoFrame &input = options_.rectification
						   ? geometry::rectify_frame(*options_.rectification, frames[i])
						   : frames[i];
		features[i] = vision::extract_stage(input, options_.motion, timing);
		if (i > 0) {
			FrameResult result;
			(void)vision::pair_stage(&features[i - 1], nullptr, features[i], input, options_.motion, result,
						 workspace);
		}
	}
}

void Pipeline::worker_loop(const std::array<StereoFrame, 2> *warm_frames)
{
	// Workers yield to the capture, dispatch and socket threads: when processing cannot keep up, frames are
	// dropped in the ring (counted as ring_overflow), not lost inside a starved camera stream. Lowering one's
	// own priority needs no privilege.
	if (options_.worker_nice > 0)
		::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), options_.worker_nice);
	vision::StageWorkspace workspace; // this worker's own, warmed up with it
	if (warm_frames != nullptr) {
		try {
			warm_up(*warm_frames, workspace);
		} catch (const std::exception &e) {
			spdlog::warn("warming a worker up: {}", e.what()); // the first frames will be slower, no more
		}
	}
	workers_warm_.count_down();
	for (;;) {
		std::unique_ptr<Job> job;
		{
			std::unique_lock lock(jobs_mutex_);
			jobs_changed_.wait(lock, [this] { return !jobs_.empty() || jobs_closed_; });
			if (jobs_.empty())
				return;
			job = std::move(jobs_.front());
			jobs_.pop_front();
		}
		jobs_changed_.notify_all();
		process(*job, workspace);
	}
}

void Pipeline::process(Job &job, vision::StageWorkspace &workspace)
{
	const StereoFrame &frame = *job.frame;
	FrameResult result;
	result.seq = frame.sequence;
	result.t_capture_ns = frame.device_ns;
	result.t_host_ns = frame.host_ns;
	result.lr_skew_ns = frame.lr_skew_ns;
	result.source = source_name_;
	result.status = frame.status;
	result.width = frame.left.cols;
	result.height = frame.left.rows;

	bool promised = false;
	bool tracks_promised = false;
	std::shared_ptr<vision::FrameFeatures> features; // this frame's, final once the pair stage returns
	try {
		if (job.provides_features && options_.motion.enabled) {
			// The vision stages see rectified eyes; the pool frame (and what the observer records) keeps
			// the camera's own pixels.
			StereoFrame rectified;
			if (options_.rectification) {
				StageTimer timer(result.timing, "rectify");
				rectified = geometry::rectify_frame(*options_.rectification, frame);
			}
			const StereoFrame &input = options_.rectification ? rectified : frame;
			features = std::make_shared<vision::FrameFeatures>(
				vision::extract_stage(input, options_.motion, result.timing));
			// Both wait only for an earlier frame that another worker already holds: no deadlock. The
			// memory makes the pair stage run in frame order; extraction, the costly part, does not wait.
			const FeaturesPtr previous = job.previous.valid() ? job.previous.get() : nullptr;
			const TracksPtr previous_tracks =
				job.previous_tracks.valid() ? job.previous_tracks.get() : nullptr;
			// The pair stage may add the corners it follows to this frame's features
			// (matching.follow_lost), so they go to the next frame only after it: the next frame waits
			// for this one's memory at the same point anyway.
			auto tracks = std::make_shared<const vision::TrackSet>(
				vision::pair_stage(previous.get(), previous_tracks.get(), *features, input,
						   options_.motion, result, workspace));
			job.features.set_value(std::move(features));
			promised = true;
			job.tracks.set_value(std::move(tracks));
			tracks_promised = true;
		}
	} catch (const std::exception &e) {
		processing_errors_.fetch_add(1);
		spdlog::error("processing frame {}: {}", frame.sequence, e.what());
		result.points.clear();
		result.ego.reset();
	}
	// After a failed pair stage the next frame still pairs with these features, starting its memory afresh
	// (as when they were published before it); the pair stage adds each corner whole.
	if (job.provides_features && !promised)
		job.features.set_value(features); // null when extraction failed: the next pairs with nothing
	if (job.provides_features && !tracks_promised)
		job.tracks.set_value(nullptr); // and its memory starts afresh
	if (observer_)
		observer_(frame);
	job.frame.reset(); // back to the pool before publishing

	{
		std::lock_guard lock(results_mutex_);
		results_.emplace(job.order, std::move(result));
	}
	results_changed_.notify_all();
}

void Pipeline::publish_loop()
{
	uint64_t next = 0;
	for (;;) {
		FrameResult result;
		{
			std::unique_lock lock(results_mutex_);
			results_changed_.wait(lock, [&] {
				return results_.count(next) > 0 || (dispatch_done_ && next >= dispatched_);
			});
			auto it = results_.find(next);
			if (it == results_.end())
				break; // everything dispatched has been published
			result = std::move(it->second);
			results_.erase(it);
		}
		++next;
		result.t_publish_ns = monotonic_ns();
		sink_(result);
		published_.fetch_add(1);
		{
			std::lock_guard lock(state_mutex_);
			latency_.add(result.t_publish_ns - result.t_host_ns);
			if (result.stereo)
				calibration_health_.add(*result.stereo);
		}
		{
			std::lock_guard lock(results_mutex_);
			published_upto_ = next;
		}
		results_changed_.notify_all();
	}
	finished_.store(true);
}

} // namespace stereod::daemon
