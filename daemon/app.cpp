#include "daemon/app.hpp"
#include "daemon/dds/dds_publisher.hpp"
#include "daemon/live_recorder.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <grp.h>
#include <iostream>
#include <pwd.h>
#include <stdexcept>
#include <thread>
#include <unistd.h>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include "core/camera/timing.hpp"
#include "core/clock.hpp"
#include "core/geometry/rectify.hpp"
#include "core/geometry/rig.hpp"
#include "core/protocol.hpp"
#include "core/vision/prior_model.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/socket_server.hpp"
#include "daemon/watchdog.hpp"
#include "drivers/calibration_file.hpp"
#include "drivers/replay/mcap_recording.hpp"

namespace stereod::daemon {
namespace {

namespace fs = std::filesystem;

/// Blocks the signals we handle in every thread (threads inherit the mask), so the main thread alone
/// receives them synchronously with sigtimedwait: no handlers, no async-signal-safety concerns.
sigset_t block_signals()
{
	sigset_t set;
	sigemptyset(&set);
	sigaddset(&set, SIGINT);
	sigaddset(&set, SIGTERM);
	sigaddset(&set, SIGHUP);
	pthread_sigmask(SIG_BLOCK, &set, nullptr);
	std::signal(SIGPIPE, SIG_IGN);
	return set;
}

/// Waits up to `seconds` for one of `set`; returns the signal or 0 on timeout.
int wait_signal(const sigset_t &set, double seconds)
{
	timespec timeout{static_cast<time_t>(seconds),
			 static_cast<long>((seconds - static_cast<double>(static_cast<time_t>(seconds))) * 1e9)};
	const int sig = sigtimedwait(&set, nullptr, &timeout);
	return sig > 0 ? sig : 0;
}

/// A fault for the service tests only (docs/testing.md): STEREOD_TEST_FAULT=hang_publish_after=N makes the
/// publisher block for good after N frames, as a hung stage would, so a test can watch systemd's watchdog act.
/// 0: no fault.
uint64_t hang_publish_after()
{
	const char *fault = std::getenv("STEREOD_TEST_FAULT");
	if (fault == nullptr || *fault == '\0')
		return 0;
	const std::string text(fault), key = "hang_publish_after=";
	char *end = nullptr;
	const unsigned long long n = text.rfind(key, 0) == 0 ? std::strtoull(text.c_str() + key.size(), &end, 10) : 0;
	if (n == 0 || end == nullptr || *end != '\0')
		throw ConfigError("STEREOD_TEST_FAULT=" + text + ": not a known fault (hang_publish_after=N, N > 0)");
	return n;
}

OverflowPolicy policy_for(const std::string &overflow, bool live)
{
	if (overflow == "drop-oldest")
		return OverflowPolicy::DropOldest;
	if (overflow == "block")
		return OverflowPolicy::Block;
	return live ? OverflowPolicy::DropOldest : OverflowPolicy::Block;
}

/// One line of the truth's camera poses in the TUM format (timestamp tx ty tz qx qy qz qw; the capture time in
/// seconds), for `stereoctl eval --poses` and any TUM tool.
std::string tum_line(int64_t t_ns, const std::array<double, 12> &world_from_camera)
{
	const auto &m = world_from_camera;
	const cv::Matx33d r(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
	const auto q = geometry::quaternion_from_rotation(r);
	return fmt::format("{:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f}\n",
			   static_cast<double>(t_ns) * 1e-9, m[3], m[7], m[11], q[0], q[1], q[2], q[3]);
}

PipelineOptions pipeline_options(const DaemonConfig &config, const drivers::SourceInfo &info, bool live)
{
	PipelineOptions options;
	options.workers =
		config.pipeline.workers > 0 ? static_cast<size_t>(config.pipeline.workers) : default_workers();
	options.ring_capacity = static_cast<size_t>(config.pipeline.ring_capacity);
	options.overflow = policy_for(config.pipeline.overflow, live);
	options.worker_nice = config.pipeline.worker_nice;
	options.warm_up = config.pipeline.warm_up && live; // a file's frames do not wait on the workers
	options.motion = config.motion;
	options.motion.rig = info.calibration;
	if (!config.calibration.file.empty()) {
		// Refused at start, before any frame: a calibration for other images gives depth that looks right
		// and is wrong.
		const std::string &path = config.calibration.file;
		geometry::PairCalibration calibration;
		try {
			calibration = drivers::read_calibration(path);
		} catch (const drivers::CalibrationError &e) {
			throw ConfigError(std::string("calibration.file: ") + e.what());
		}
		if (!info.geometry.stereo)
			throw ConfigError("calibration.file: " + path + ": source '" + info.name +
					  "' has no right eye");
		const cv::Size image(info.geometry.width, info.geometry.height);
		const auto problems = geometry::calibration_problems(calibration, image);
		if (!problems.empty()) {
			std::string message = "calibration.file: " + path + " does not fit source '" + info.name + "':";
			for (const auto &problem : problems)
				message += "\n  - " + problem;
			throw ConfigError(message);
		}
		auto rectification =
			std::make_shared<geometry::Rectification>(geometry::make_rectification(calibration, image));
		options.motion.rig = rectification->rig;
		spdlog::info("calibration: {} (rectified: f {:.1f} px, baseline {:.4f} m)", path, rectification->rig.fx,
			     rectification->rig.baseline_m);
		options.rectification = std::move(rectification);
	}
	auto &prior = options.motion.prior;
	if (prior.enabled && prior.detector == vision::PriorDetector::Onnx) {
		// Loaded once, here: a missing or unfit model stops the start with the reason, not the first frame.
		const std::string &path = prior.model_path;
		if (path.empty())
			throw ConfigError("prior.model: name the ONNX file (prior.detector = \"onnx\")");
		std::ifstream file(path, std::ios::binary);
		if (!file)
			throw ConfigError("prior.model: " + path + ": cannot open: " + std::strerror(errno));
		const std::vector<char> bytes{std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>()};
		try {
			prior.model = std::make_shared<const vision::PriorModel>(bytes, prior.model_spec);
		} catch (const vision::PriorModelError &e) {
			throw ConfigError("prior.model: " + path + ": " + e.what());
		}
		spdlog::info("prior: {} ({} classes out, {}x{} input, {})", path, prior.model->output_classes(),
			     prior.model_spec.input_width, prior.model_spec.input_height,
			     vision::format_class_map(prior.model_spec.classes));
	}
	return options;
}

/// One status message from one snapshot of each component's counters, so its numbers agree with each other.
protocol::StatusReport make_status(const Pipeline &pipeline, const PipelineStats &s, const SocketServerStats &server,
				   int64_t start_ns, double capture_fps, double publish_fps)
{
	protocol::StatusReport report;
	report.t_host_ns = monotonic_ns();
	report.uptime_s = static_cast<double>(report.t_host_ns - start_ns) * 1e-9;
	report.source = pipeline.source_info().name;
	report.source_state = s.source_state;
	report.capture_fps = capture_fps;
	report.publish_fps = publish_fps;
	report.frames_captured = s.frames_captured;
	report.frames_published = s.frames_published;
	report.drops = {{"ring_overflow", s.ring_evicted},
			{"pool_exhausted", s.pool_exhausted},
			{"source_gap", s.source_gaps},
			{"corrupt", s.corrupt},
			{"processing_error", s.processing_errors}};
	const drivers::SourceCounters source = pipeline.source_counters();
	for (const auto &[name, count] : source.drops)
		report.drops[name] = count;
	report.device = source.device;
	report.drops["client_queue"] = server.messages_dropped;
	report.drops["clients_dropped"] = server.clients_dropped;
	report.drops["clients_refused"] = server.clients_refused;
	report.drops["clients_denied"] = server.clients_denied;
	report.clients = server.clients;
	report.capture_to_publish = s.capture_to_publish;
	report.stereo = s.stereo;
	return report;
}

/// Frames per second from counter deltas between two status ticks.
class RateMeter
{
public:
	std::pair<double, double> update(uint64_t captured, uint64_t published)
	{
		const int64_t now = monotonic_ns();
		const double dt = static_cast<double>(now - last_ns_) * 1e-9;
		std::pair<double, double> rates{0, 0};
		if (last_ns_ != 0 && dt > 0)
			rates = {static_cast<double>(captured - last_captured_) / dt,
				 static_cast<double>(published - last_published_) / dt};
		last_ns_ = now;
		last_captured_ = captured;
		last_published_ = published;
		return rates;
	}

private:
	int64_t last_ns_ = 0;
	uint64_t last_captured_ = 0, last_published_ = 0;
};

void set_log_level(const std::string &level)
{
	spdlog::set_level(spdlog::level::from_str(level));
}

} // namespace

size_t default_workers()
{
	const unsigned cores = std::thread::hardware_concurrency();
	return cores > 0 ? cores : 2;
}

std::string driver_for_format(const std::string &format, const std::string &path)
{
	if (format == "recording" || format == "replay" || format == "srec" || format == "mcap")
		return "replay";
	if (format == "video" || format == "kitti" || format == "euroc" || format == "tum" || format == "folder" ||
	    format == "sim")
		return format;
	if (format != "auto")
		throw ConfigError("--format " + format +
				  ": unknown (known: auto, recording, video, kitti, euroc, tum, folder, sim)");
	const fs::path p(path);
	std::error_code ec;
	if (fs::is_directory(p, ec)) {
		if (fs::exists(p / "image_02", ec))
			return "kitti";
		if (fs::exists(p / "mav0", ec))
			return "euroc";
		if (fs::exists(p / "rgb.txt", ec))
			return "tum";
		if (fs::exists(p / "left", ec))
			return "folder";
		throw ConfigError("--input " + path + ": cannot tell the dataset layout; give --format");
	}
	if (p.extension() == ".srec" || p.extension() == ".mcap")
		return "replay";
	return "video";
}

namespace {

/// A user or group given by name or number, as this machine knows it; ConfigError naming the key otherwise.
uint32_t resolve_id(const std::string &key, const std::string &name, bool is_group)
{
	char *end = nullptr;
	const unsigned long number = std::strtoul(name.c_str(), &end, 10);
	if (!name.empty() && end != nullptr && *end == '\0')
		return static_cast<uint32_t>(number);
	if (is_group) {
		if (const struct group *g = ::getgrnam(name.c_str()))
			return g->gr_gid;
	} else if (const struct passwd *p = ::getpwnam(name.c_str())) {
		return p->pw_uid;
	}
	throw ConfigError("output." + key + ": no " + (is_group ? "group" : "user") + " '" + describe_cut(name) +
			  "' on this machine");
}

SocketServerOptions server_options(const OutputConfig &output)
{
	SocketServerOptions o;
	o.path = output.socket;
	o.mode = output.socket_mode;
	o.client_queue = static_cast<size_t>(output.client_queue);
	o.client_max_input = static_cast<size_t>(output.client_max_input);
	o.max_clients = static_cast<size_t>(output.max_clients);
	o.client_queue_bytes = static_cast<size_t>(output.client_queue_bytes);
	for (const auto &user : output.allow_users)
		o.allow_uids.push_back(resolve_id("allow_users", user, false));
	for (const auto &group : output.allow_groups)
		o.allow_gids.push_back(resolve_id("allow_groups", group, true));
	if (!output.socket_group.empty())
		o.socket_gid = resolve_id("socket_group", output.socket_group, true);
	return o;
}

/// The options a reload applies while everything keeps running; any other change rebuilds the source and the
/// pipeline in place (clients stay connected), except the socket's path, which needs a restart.
bool applies_live(const std::string &option)
{
	return option == "log.level" || option == "output.status_interval_s" || option == "output.socket_mode" ||
	       option == "output.client_queue" || option == "output.client_queue_bytes" ||
	       option == "output.max_clients" || option == "output.client_max_input" ||
	       option == "output.socket_group" || option == "output.allow_users" || option == "output.allow_groups";
}

} // namespace

int run_daemon(const DaemonConfig &initial, const std::function<DaemonConfig()> &reload)
{
	DaemonConfig config = initial;
	set_log_level(config.log.level);
	const sigset_t signals = block_signals();
	const auto registry = drivers::SourceRegistry::with_builtin_drivers();
	// Made with the first source, so that its first client already gets the right `hello`.
	std::unique_ptr<SocketServer> server;
	const uint64_t hang_after = hang_publish_after();
	uint64_t sunk = 0; // publisher thread only

	auto hello_for = [](const drivers::SourceInfo &info) {
		return protocol::hello_message(monotonic_ns(), info.name, info.geometry.width, info.geometry.height);
	};
	// DDS, when on: made once, before any pipeline (which publishes into it) and outliving them all. Its
	// options apply at start only.
	std::unique_ptr<DdsPublisher> dds;
	if (config.dds.enabled) {
		try {
			dds = std::make_unique<DdsPublisher>(config.dds);
		} catch (const std::runtime_error &e) {
			throw ConfigError("dds.enabled: " + std::string(e.what()));
		}
	}
	// The source and the pipeline: built at start, and again in place when a reload changes what they use.
	PipelineOptions options;
	// The live recording, when on: shared with the pipeline's frame observer, so a pipeline being replaced
	// keeps its recorder until its last frame is offered.
	std::shared_ptr<LiveRecorder> recorder;
	auto build_pipeline = [&](const DaemonConfig &c) {
		auto source = registry.create(c.source);
		const drivers::SourceInfo info = source->info();
		spdlog::info("source: {} ({}x{} {}, {}{} fps {})", info.description, info.geometry.width,
			     info.geometry.height, to_string(info.geometry.format),
			     info.geometry.stereo ? "stereo, " : "", info.geometry.depth ? "depth, " : "",
			     info.geometry.nominal_fps);
		PipelineOptions o = pipeline_options(c, info, info.live);
		std::string hello = hello_for(info);
		if (!server) {
			SocketServerOptions server_opts = server_options(c.output);
			server_opts.greeting = std::move(hello);
			server = std::make_unique<SocketServer>(std::move(server_opts));
		} else {
			server->set_greeting(std::move(hello));
		}
		recorder.reset();
		if (!c.record.path.empty()) {
			drivers::RecorderOptions record_options;
			record_options.images = c.record.images;
			record_options.results = c.record.results;
			try {
				recorder = std::make_shared<LiveRecorder>(
					c.record.path,
					drivers::RecordingHeader::stamped_now(info.name, info.description,
									      info.geometry),
					static_cast<size_t>(c.record.buffer_frames), c.record.sync, record_options);
			} catch (const std::runtime_error &e) {
				throw ConfigError("record.path: " + std::string(e.what()));
			}
		}
		// The sink holds its own reference: a pipeline being replaced keeps its recorder until it is gone.
		std::shared_ptr<LiveRecorder> result_recorder =
			recorder && recorder->records_results() ? recorder : nullptr;
		auto built = std::make_unique<Pipeline>(
			std::move(source), o,
			[&server, &dds, hang_after, &sunk, rec = std::move(result_recorder)](FrameResult &result) {
				if (hang_after > 0 && ++sunk > hang_after) {
					spdlog::warn("STEREOD_TEST_FAULT: the publisher hangs from frame {} on",
						     result.seq);
					for (;;)
						std::this_thread::sleep_for(std::chrono::hours(1));
				}
				std::string message = protocol::frame_message(result);
				if (rec)
					rec->offer_result(result.t_capture_ns, message);
				if (dds)
					dds->offer(result);
				server->publish(std::move(message));
			});
		if (recorder)
			built->set_frame_observer([rec = recorder](const StereoFrame &frame) { rec->offer(frame); });
		built->start();
		spdlog::info("streaming on {} ({} workers, ring {} {})", c.output.socket, o.workers, o.ring_capacity,
			     to_string(o.overflow));
		options = o;
		return built;
	};
	std::unique_ptr<Pipeline> pipeline = build_pipeline(config);
	auto notify_ready = [&] {
		sd_notifyf(0, "READY=1\nSTATUS=streaming %s on %s", pipeline->source_info().name.c_str(),
			   config.output.socket.c_str());
	};
	// READY=1 waits for the first published frame: "started" means results flow, not that a socket exists.
	sd_notifyf(0, "STATUS=starting: waiting for the first frame from %s", pipeline->source_info().name.c_str());
	bool ready = false;

	uint64_t watchdog_usec = 0;
	const bool watchdog = sd_watchdog_enabled(0, &watchdog_usec) > 0;
	auto tick_for = [&](const DaemonConfig &c) {
		double tick = c.output.status_interval_s;
		return watchdog ? std::min(tick, static_cast<double>(watchdog_usec) * 1e-6 / 2) : tick;
	};
	double tick_s = tick_for(config);
	const auto watchdog_limit_ns = static_cast<int64_t>(watchdog_usec) * 1000;
	WatchdogSample last_sample{0, 0, monotonic_ns()};
	bool watchdog_withheld = false;

	// What reloads that rebuilt the pipeline cost a live source (status `drops.reload`): the frames it sent
	// between the old pipeline's last capture and the new one's first, at the old source's nominal rate
	// (an outage of the daemon's own making, counted as a camera's), and the old backlog its drain left
	// unprocessed. The new pipeline's own counters start at zero with its `hello`; this one does not.
	camera::OutageCounter reload_gap;
	uint64_t reload_unprocessed = 0;
	int64_t reload_gap_from_ns = 0; // the old pipeline's last capture while a gap is open
	const auto close_reload_gap = [&](const PipelineStats &s) {
		if (reload_gap_from_ns > 0 && s.first_capture_host_ns > 0) {
			const uint64_t before = reload_gap.lost();
			reload_gap.delivered(s.first_capture_host_ns);
			spdlog::info("reload: capture paused {:.0f} ms, {} frames of the live source not captured "
				     "(drops.reload)",
				     static_cast<double>(s.first_capture_host_ns - reload_gap_from_ns) * 1e-6,
				     reload_gap.lost() - before);
			reload_gap_from_ns = 0;
		}
	};

	const int64_t start_ns = monotonic_ns();
	int64_t next_status_ns = start_ns + static_cast<int64_t>(config.output.status_interval_s * 1e9);
	int64_t next_log_ns = start_ns + 10'000'000'000;
	RateMeter meter;
	bool calibration_warned = false;
	auto emit_status = [&] {
		const SocketServerStats server_stats = server->stats();
		const PipelineStats s = pipeline->stats();
		close_reload_gap(s);
		const auto [capture_fps, publish_fps] = meter.update(s.frames_captured, s.frames_published);
		auto report = make_status(*pipeline, s, server_stats, start_ns, capture_fps, publish_fps);
		report.drops["reload"] = reload_gap.lost() + reload_unprocessed;
		if (recorder)
			report.recording = recorder->stats();
		if (dds) {
			const auto d = dds->stats();
			report.dds = protocol::StatusReport::Dds{
				config.dds.name, config.dds.domain, d.frames_published, d.frames_dropped,
				d.write_errors,	 d.publish_ms_mean, d.publish_ms_max};
			dds->offer_status(report);
		}
		server->publish(protocol::status_message(report));
		uint64_t frames_dropped = 0;
		for (const auto &[name, count] : report.drops)
			frames_dropped += name.rfind("client", 0) == 0 ? 0 : count; // those count messages or clients
		sd_notifyf(0, "STATUS=%s %s: %.1f fps, %llu frames dropped, %zu clients", report.source_state.c_str(),
			   report.source.c_str(), report.publish_fps, static_cast<unsigned long long>(frames_dropped),
			   report.clients);
		// Said once per crossing, not every status: a bumped rig needs recalibrating, not a flood of lines.
		const bool drifted = report.stereo && report.stereo->drifted;
		if (drifted != calibration_warned) {
			if (drifted)
				spdlog::warn("stereo calibration drifting: matches differ by {:.2f} px in rows (over "
					     "0.5 px); "
					     "{:.1f}% refused by the epipolar band; the rig needs recalibrating",
					     report.stereo->row_diff_px, 100 * report.stereo->outside_band_fraction);
			else
				spdlog::info("stereo calibration back within 0.5 px ({:.2f} px)",
					     report.stereo ? report.stereo->row_diff_px : 0.0);
			calibration_warned = drifted;
		}
		return report;
	};

	// SIGHUP: read the configuration again. A config that fails to load or validate is refused with its
	// file, line and key, and the running one stays. Live options apply at once; anything the source or
	// the pipeline uses rebuilds them in place (the old pipeline drains first); clients stay connected.
	auto reload_config = [&] {
		const auto now_us = static_cast<unsigned long long>(monotonic_ns() / 1000);
		sd_notifyf(0, "RELOADING=1\nMONOTONIC_USEC=%llu\nSTATUS=reloading the configuration", now_us);
		if (!reload) {
			spdlog::warn("SIGHUP: no configuration file to read again (started without --config); nothing "
				     "to do");
		} else {
			try {
				DaemonConfig next = reload();
				if (next.output.socket != config.output.socket) {
					spdlog::warn("reload: output.socket changes only with a restart; still {}",
						     config.output.socket);
					next.output.socket = config.output.socket;
				}
				if (!(next.dds == config.dds))
					spdlog::warn("reload: dds.* changes only with a restart; still as started");
				next.dds = config.dds;
				const SocketServerOptions next_server = server_options(next.output); // may refuse
				const std::vector<std::string> changed = changed_options(config, next);
				const bool rebuild = std::any_of(changed.begin(), changed.end(),
								 [](const std::string &o) { return !applies_live(o); });
				set_log_level(next.log.level);
				server->set_limits(next_server);
				tick_s = tick_for(next);
				if (rebuild) {
					spdlog::info("reload: rebuilding the source and the pipeline");
					pipeline->request_stop();
					pipeline->wait();
					const PipelineStats old = pipeline->stats();
					const drivers::SourceInfo &old_info = pipeline->source_info();
					reload_unprocessed += old.dropped_at_stop;
					if (old_info.live && old.last_capture_host_ns > 0) {
						reload_gap.set_rate(old_info.geometry.nominal_fps);
						reload_gap.delivered(old.last_capture_host_ns);
						reload_gap.reconnected();
						reload_gap_from_ns = old.last_capture_host_ns;
					}
					pipeline.reset();
					try {
						pipeline = build_pipeline(next);
					} catch (const std::exception &e) {
						spdlog::error(
							"reload: the new source or pipeline failed ({}); back to the "
							"running configuration",
							e.what());
						pipeline = build_pipeline(config);
						next = config;
					}
					// A file or a batch source loses nothing while it waits: the gap closes
					// uncounted.
					if (reload_gap_from_ns > 0 && !pipeline->source_info().live) {
						reload_gap.delivered(reload_gap_from_ns);
						reload_gap_from_ns = 0;
					}
					meter = RateMeter();
					last_sample = {0, 0, monotonic_ns()};
					// Connected clients hear of the new source (its frames' seq start again) as a
					// new client would.
					server->publish(hello_for(pipeline->source_info()));
				}
				std::string list;
				for (const auto &option : changed)
					list += (list.empty() ? "" : ", ") + option;
				spdlog::info("reload: {}", changed.empty() ? "nothing changed" : "applied " + list);
				config = std::move(next);
			} catch (const std::exception &e) {
				spdlog::error("reload refused, the running configuration stays: {}", e.what());
			}
		}
		// Neither the new source nor the running configuration's could be opened again: nothing left to
		// run (systemd's Restart=on-failure takes over).
		if (!pipeline)
			throw std::runtime_error("reload: no source could be opened, neither the new configuration's "
						 "nor the running one's");
		notify_ready();
	};

	for (;;) {
		const int sig = wait_signal(signals, ready ? tick_s : std::min(tick_s, 0.05));
		if (sig == SIGTERM || sig == SIGINT) {
			spdlog::info("{}: draining and stopping", sig == SIGTERM ? "SIGTERM" : "SIGINT");
			sd_notify(0, "STOPPING=1");
			pipeline->request_stop();
			pipeline->wait();
			break;
		}
		if (sig == SIGHUP)
			reload_config();
		const PipelineStats snapshot = pipeline->stats();
		if (!ready && snapshot.frames_published > 0) {
			ready = true;
			spdlog::info("first frame published: ready");
			notify_ready();
		}
		if (watchdog) {
			const WatchdogSample sample{snapshot.frames_captured, snapshot.frames_published,
						    snapshot.capture_turn_ns};
			const bool alive = pipeline_alive(last_sample, sample, monotonic_ns(), watchdog_limit_ns);
			if (alive)
				sd_notify(0, "WATCHDOG=1");
			if (alive == watchdog_withheld) { // said once per change, not every tick
				watchdog_withheld = !alive;
				if (alive)
					spdlog::info("watchdog: frames get through again; pinging");
				else
					spdlog::error("watchdog: {}; not pinging (systemd will restart the service)",
						      sample.captured > last_sample.captured
							      ? "frames come in but none are published"
							      : "the capture loop stopped turning");
			}
			last_sample = sample;
		}
		const int64_t now = monotonic_ns();
		if (now >= next_status_ns) {
			next_status_ns = now + static_cast<int64_t>(config.output.status_interval_s * 1e9);
			const auto report = emit_status();
			if (now >= next_log_ns) {
				next_log_ns = now + 10'000'000'000;
				const SocketServerStats clients = server->stats();
				spdlog::info(
					"status: {} {:.1f} fps captured, {:.1f} published, latency p50 {:.1f} ms p99 "
					"{:.1f} ms, {} clients ({} connected, {} hung up, {} dropped, {} refused "
					"since start)",
					report.source_state, report.capture_fps, report.publish_fps,
					report.capture_to_publish.p50_ms, report.capture_to_publish.p99_ms,
					report.clients, clients.accepted, clients.clients_closed,
					clients.clients_dropped, clients.clients_refused);
			}
		}
		if (pipeline->finished()) {
			spdlog::info("source finished");
			for (const auto &line : pipeline->source_report())
				spdlog::info("{}", line);
			break;
		}
	}
	emit_status();
	const auto final_stats = pipeline->stats();
	spdlog::info("stopped: {} frames captured, {} published{}", final_stats.frames_captured,
		     final_stats.frames_published,
		     final_stats.dropped_at_stop > 0
			     ? fmt::format(", {} left unprocessed when the {:.1f} s drain ran out",
					   final_stats.dropped_at_stop,
					   static_cast<double>(options.drain_limit_ns) * 1e-9)
			     : std::string());
	return 0;
}

int run_batch(DaemonConfig config, const BatchOptions &options)
{
	set_log_level(config.log.level);
	const sigset_t signals = block_signals();
	config.source.realtime = false;
	if (config.source.driver != "sim") {
		std::error_code ec;
		if (!fs::exists(config.source.path, ec))
			throw ConfigError("--input " + config.source.path + ": no such file or directory");
	}
	const auto registry = drivers::SourceRegistry::with_builtin_drivers();
	auto source = registry.create(config.source);
	const drivers::SourceInfo info = source->info();

	std::ofstream file;
	std::ostream *out = &std::cout;
	// MCAP output: the results channel, and with --images the eyes as JPEG, encoded on the workers (the
	// observer) and written in frame order with their result (the sink).
	std::unique_ptr<drivers::McapRecorder> mcap;
	std::mutex images_mutex;
	std::map<uint64_t, std::pair<std::string, std::string>> images;
	if (drivers::is_mcap_path(options.output)) {
		drivers::RecorderOptions mcap_options;
		mcap_options.raw = false;
		mcap_options.images = options.images;
		mcap_options.results = true;
		try {
			mcap = std::make_unique<drivers::McapRecorder>(
				options.output,
				drivers::RecordingHeader::stamped_now(info.name, info.description, info.geometry),
				mcap_options);
		} catch (const std::runtime_error &e) {
			throw ConfigError("--output " + std::string(e.what()));
		}
	} else if (options.images) {
		throw ConfigError("--images: only MCAP output (.mcap) carries images");
	} else if (options.output != "-") {
		file.open(options.output, std::ios::binary | std::ios::trunc);
		if (!file)
			throw ConfigError("--output " + options.output + ": cannot create file");
		out = &file;
	}

	// Truth export: one mask PNG per frame and one truth.ndjson line per frame, sorted at the end.
	const bool export_truth = !options.truth_dir.empty() && info.geometry.truth;
	if (!options.truth_dir.empty() && !info.geometry.truth)
		spdlog::warn("--truth-dir: source '{}' has no ground truth; nothing written there", info.name);
	std::mutex truth_mutex;
	std::map<uint64_t, std::string> truth_lines, pose_lines;
	if (export_truth)
		fs::create_directories(fs::path(options.truth_dir) / "masks");
	if (export_truth && info.geometry.depth)
		fs::create_directories(fs::path(options.truth_dir) / "depth");

	PipelineOptions pipeline_opts = pipeline_options(config, info, false);
	pipeline_opts.overflow = OverflowPolicy::Block; // batch never drops
	std::string mcap_error;
	Pipeline pipeline(std::move(source), pipeline_opts, [&](FrameResult &result) {
		if (!mcap) {
			*out << protocol::frame_message(result) << '\n';
			return;
		}
		if (!mcap_error.empty())
			return;
		try {
			std::pair<std::string, std::string> eyes;
			if (options.images) {
				std::lock_guard lock(images_mutex);
				auto it = images.find(result.seq);
				if (it != images.end()) {
					eyes = std::move(it->second);
					images.erase(it);
				}
			}
			if (!eyes.first.empty())
				mcap->append_image_message(result.t_capture_ns, false, eyes.first, true);
			if (!eyes.second.empty())
				mcap->append_image_message(result.t_capture_ns, true, eyes.second, true);
			mcap->append_result(result.t_capture_ns, protocol::frame_message(result));
		} catch (const std::exception &e) {
			mcap_error = e.what(); // reported at the end; the frames go on being processed
		}
	});
	const auto encode_images = [&](const StereoFrame &frame) {
		std::pair<std::string, std::string> eyes{
			drivers::McapRecorder::image_message(frame.left, frame.device_ns, "left", 90),
			frame.right.empty()
				? std::string()
				: drivers::McapRecorder::image_message(frame.right, frame.device_ns, "right", 90)};
		std::lock_guard lock(images_mutex);
		images[frame.sequence] = std::move(eyes);
	};
	if (options.images && !export_truth)
		pipeline.set_frame_observer(encode_images);
	if (export_truth) {
		pipeline.set_frame_observer([&](const StereoFrame &frame) {
			if (options.images)
				encode_images(frame);
			char name[32];
			std::snprintf(name, sizeof(name), "masks/%06llu.png",
				      static_cast<unsigned long long>(frame.sequence));
			cv::imwrite((fs::path(options.truth_dir) / name).string(), frame.truth.object_ids);
			if (!frame.depth.empty()) {
				// The true depth as 16-bit millimetres (0 = unknown), for `stereoctl eval`'s depth
				// score.
				char depth_name[32];
				std::snprintf(depth_name, sizeof(depth_name), "depth/%06llu.png",
					      static_cast<unsigned long long>(frame.sequence));
				cv::Mat mm;
				frame.depth.convertTo(mm, CV_16U, 1000.0);
				cv::imwrite((fs::path(options.truth_dir) / depth_name).string(), mm);
			}
			nlohmann::json objects = nlohmann::json::array();
			for (size_t i = 0; i < frame.truth.object_count; ++i) {
				const auto &o = frame.truth.objects[i];
				objects.push_back(
					{{"id", o.id}, {"position_m", o.position_m}, {"velocity_mps", o.velocity_mps}});
			}
			const nlohmann::json line = {{"seq", frame.sequence},
						     {"t_capture_ns", frame.device_ns},
						     {"camera_pose", frame.truth.camera_pose},
						     {"objects", std::move(objects)},
						     {"mask", name}};
			std::string pose = tum_line(frame.device_ns, frame.truth.camera_pose);
			std::lock_guard lock(truth_mutex);
			truth_lines[frame.sequence] = line.dump();
			pose_lines[frame.sequence] = std::move(pose);
		});
	}

	const bool show_progress = options.progress && ::isatty(STDERR_FILENO);
	const int64_t start_ns = monotonic_ns();
	pipeline.start();
	bool interrupted = false;
	while (!pipeline.finished()) {
		const int sig = wait_signal(signals, 0.1);
		if ((sig == SIGINT || sig == SIGTERM) && !interrupted) {
			interrupted = true;
			spdlog::warn("interrupted: finishing the frames already read");
			pipeline.request_stop();
		}
		if (show_progress) {
			const auto s = pipeline.stats();
			const uint64_t total = info.frame_count;
			const double elapsed = static_cast<double>(monotonic_ns() - start_ns) * 1e-9;
			const double fps = elapsed > 0 ? static_cast<double>(s.frames_published) / elapsed : 0;
			std::string bar;
			if (total > 0) {
				const auto filled = static_cast<size_t>(30.0 * static_cast<double>(s.frames_published) /
									static_cast<double>(total));
				bar = "[" + std::string(std::min<size_t>(filled, 30), '#') +
				      std::string(30 - std::min<size_t>(filled, 30), ' ') + "] ";
			}
			std::fprintf(stderr, "\r%s%llu%s frames  %.1f fps ", bar.c_str(),
				     static_cast<unsigned long long>(s.frames_published),
				     total > 0 ? ("/" + std::to_string(total)).c_str() : "", fps);
		}
	}
	pipeline.wait();
	if (show_progress)
		std::fprintf(stderr, "\n");
	out->flush();
	if (export_truth) {
		std::ofstream truth(fs::path(options.truth_dir) / "truth.ndjson", std::ios::trunc);
		for (const auto &[seq, line] : truth_lines)
			truth << line << '\n';
		std::ofstream poses(fs::path(options.truth_dir) / "poses.tum", std::ios::trunc);
		poses << "# the source's true camera poses: world from left camera (x right, y down, z forward), "
			 "metres\n# timestamp tx ty tz qx qy qz qw\n";
		for (const auto &[seq, line] : pose_lines)
			poses << line;
	}
	const auto s = pipeline.stats();
	const double elapsed = static_cast<double>(monotonic_ns() - start_ns) * 1e-9;
	spdlog::info("processed {} frames in {:.2f} s ({:.1f} fps); {} corrupt, {} processing errors",
		     s.frames_published, elapsed, elapsed > 0 ? static_cast<double>(s.frames_published) / elapsed : 0.0,
		     s.corrupt, s.processing_errors);
	for (const auto &line : pipeline.source_report())
		spdlog::info("{}", line);
	// A source that announced its length and ended early (a video cut short) says so.
	if (!interrupted && info.frame_count > 0 && s.frames_captured < info.frame_count)
		spdlog::warn("the input ended early: {} announced {} frames, {} were read ({} missing)", info.name,
			     info.frame_count, s.frames_captured, info.frame_count - s.frames_captured);
	if (mcap) {
		if (mcap_error.empty()) {
			try {
				mcap->finish();
			} catch (const std::exception &e) {
				mcap_error = e.what();
			}
		}
		if (!mcap_error.empty())
			throw ConfigError("--output " + mcap_error);
		spdlog::info("wrote {} ({} bytes)", options.output, mcap->bytes_written());
	}
	if (!*out)
		throw ConfigError("--output " + options.output + ": write failed");
	return interrupted ? 130 : 0;
}

} // namespace stereod::daemon
