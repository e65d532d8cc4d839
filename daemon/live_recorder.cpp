#include "daemon/live_recorder.hpp"

#include <algorithm>
#include <chrono>
#include <filesystem>

#include <spdlog/spdlog.h>

namespace stereod::daemon {

namespace {

/// A recording already at `path` (an earlier run, or the run before a reload) is kept: moved aside to
/// `path.<n>` with the first free n, never overwritten.
const std::string &keep_existing(const std::string &path)
{
	namespace fs = std::filesystem;
	std::error_code ec;
	if (!fs::exists(path, ec) || fs::file_size(path, ec) == 0)
		return path;
	for (int n = 1; n < 100000; ++n) {
		const std::string aside = path + "." + std::to_string(n);
		if (fs::exists(aside, ec))
			continue;
		fs::rename(path, aside, ec);
		if (!ec)
			spdlog::info("recording: the earlier {} is kept as {}", path, aside);
		break;
	}
	return path;
}

} // namespace

LiveRecorder::LiveRecorder(const std::string &path, const drivers::RecordingHeader &header, size_t slots, bool sync,
			   const drivers::RecorderOptions &options)
	: path_(path), writer_(drivers::open_recorder(keep_existing(path), header, options)), sync_(sync),
	  slots_(std::max<size_t>(slots, 1))
{
	records_results_ = writer_->records_results();
	results_.reserve(slots_.size() * 4);
	writing_.reserve(slots_.size() * 4);
	for (size_t i = 0; i < slots_.size(); ++i) {
		slots_[i].allocate(header.geometry);
		free_.push_back(i);
	}
	queued_.reserve(slots_.size());
	thread_ = std::thread([this] { write_loop(); });
	spdlog::info("recording to {} ({} frames buffered)", path_, slots_.size());
}

LiveRecorder::~LiveRecorder()
{
	{
		std::lock_guard lock(mutex_);
		stopping_ = true;
	}
	queued_cv_.notify_all();
	thread_.join();
	if (!failed_) {
		try {
			writer_->finish(); // MCAP's summary and footer; a file cut before them still reads
		} catch (const std::exception &e) {
			failed_ = true;
			error_ = e.what();
		}
		bytes_ = writer_->bytes_written();
	}
	const auto s = stats();
	spdlog::info("recording {}: {} frames, {} bytes{}{}", path_, s.frames, s.bytes,
		     s.dropped > 0 ? ", " + std::to_string(s.dropped) + " frames not recorded (disk too slow)" : "",
		     s.error.empty() ? "" : "; stopped early: " + s.error);
}

void LiveRecorder::offer(const StereoFrame &frame)
{
	size_t slot = 0;
	{
		std::lock_guard lock(mutex_);
		if (failed_ || stopping_)
			return;
		if (free_.empty()) {
			dropped_.fetch_add(1);
			return;
		}
		slot = free_.back();
		free_.pop_back();
	}
	frame.copy_to(slots_[slot]); // outside the lock: the slot is this thread's until queued
	{
		std::lock_guard lock(mutex_);
		queued_.push_back(slot);
	}
	queued_cv_.notify_one();
}

void LiveRecorder::write_loop()
{
	std::unique_lock lock(mutex_);
	for (;;) {
		// Workers finish frames a little out of order: wait briefly for a second frame so that the file is
		// in sequence order within that window.
		queued_cv_.wait(lock, [&] { return stopping_ || !queued_.empty() || !results_.empty(); });
		if (!results_.empty()) {
			writing_.swap(results_);
			const bool failed = failed_;
			lock.unlock();
			std::string error;
			try {
				for (const auto &[t, message] : writing_)
					if (!failed)
						writer_->append_result(t, message);
			} catch (const std::exception &e) {
				error = e.what();
			}
			writing_.clear();
			lock.lock();
			if (!error.empty() && !failed_) {
				failed_ = true;
				error_ = error;
				spdlog::error("recording stopped: {} (everything complete before is kept in {}); the "
					      "stream goes on",
					      error, path_);
			}
			continue;
		}
		if (queued_.empty() && stopping_)
			return;
		if (queued_.size() < 2 && !stopping_)
			queued_cv_.wait_for(lock, std::chrono::milliseconds(20),
					    [&] { return stopping_ || queued_.size() >= 2; });
		const auto oldest = std::min_element(queued_.begin(), queued_.end(), [&](size_t a, size_t b) {
			return slots_[a].sequence < slots_[b].sequence;
		});
		const size_t slot = *oldest;
		queued_.erase(oldest);
		const bool failed = failed_;
		lock.unlock();
		std::string error;
		if (!failed) {
			try {
				writer_->append(slots_[slot], sync_);
			} catch (const std::exception &e) {
				error = e.what();
			}
		}
		lock.lock();
		free_.push_back(slot);
		if (!error.empty() && !failed_) {
			failed_ = true;
			error_ = error;
			spdlog::error("recording stopped: {} ({} complete frames kept in {}); the stream goes on",
				      error, writer_->frames_written(), path_);
		}
		frames_ = writer_->frames_written();
		bytes_ = writer_->bytes_written();
	}
}

void LiveRecorder::offer_result(int64_t t_capture_ns, std::string message)
{
	if (!records_results_)
		return;
	{
		std::lock_guard lock(mutex_);
		if (failed_ || stopping_)
			return;
		if (results_.size() >= slots_.size() * 4) {
			dropped_.fetch_add(1);
			return;
		}
		results_.emplace_back(t_capture_ns, std::move(message));
	}
	queued_cv_.notify_one();
}

protocol::StatusReport::Recording LiveRecorder::stats() const
{
	std::lock_guard lock(mutex_);
	protocol::StatusReport::Recording r;
	r.path = path_;
	r.state = failed_ ? "failed" : (stopping_ ? "stopped" : "recording");
	r.error = error_;
	r.frames = frames_;
	r.bytes = bytes_;
	r.dropped = dropped_.load();
	return r;
}

} // namespace stereod::daemon
