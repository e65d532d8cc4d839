// Benchmark (not a test): the daemon's pipeline on the live sim at its frame rate, capture-to-publish
// latency percentiles and throughput, with the vision stages off (the spine alone), on the left eye (the
// monocular ORB path) and on the whole stereo path (both eyes' features, stereo, pose, geometric check), the
// last also with the stereo stage's other ways: seed 002's descriptor matching alone, the row search alone.
// With --dds, the stereo path again with the daemon's publisher: NDJSON messages only (DDS off), NDJSON + DDS
// with no subscriber, and NDJSON + DDS with a subscriber in another participant taking every sample: issue
// 18's "p99 within 10 % of DDS off", measured in one run.
// With --prerendered the sim's frames are rendered before the runs and played back at the frame rate: the sim
// draws two 1024x768 eyes in tens of milliseconds of CPU a frame (printed), which a camera does not take
// from the host, so without it the pipeline shares its two cores with the renderer.
#include <atomic>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <dds/dds.h>
#include <spdlog/spdlog.h>

#include "core/clock.hpp"
#include "core/latency.hpp"
#include "core/protocol.hpp"
#include "daemon/app.hpp"
#include "daemon/dds/dds_publisher.hpp"
#include "daemon/pipeline.hpp"
#include "drivers/replay/pacer.hpp"
#include "ros2_types.h"

using namespace stereod;

namespace {

/// CPU time of the whole process (every thread), seconds.
double process_cpu_s()
{
	rusage usage{};
	getrusage(RUSAGE_SELF, &usage);
	const auto seconds = [](const timeval &t) { return static_cast<double>(t.tv_sec) + t.tv_usec * 1e-6; };
	return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

/// The sim's frames rendered once, before any run, shared by every run that plays them.
struct RenderedFrames {
	drivers::SourceInfo info;
	std::vector<StereoFrame> frames;
	double render_cpu_ms = 0; ///< process CPU per frame while rendering (both eyes and the truth)
};

std::shared_ptr<const RenderedFrames> prerender(drivers::SourceConfig config, double seconds)
{
	auto out = std::make_shared<RenderedFrames>();
	config.realtime = false;
	config.sim.frames = static_cast<uint64_t>(std::ceil(seconds * config.sim.fps)) + 30;
	auto source = drivers::SourceRegistry::with_builtin_drivers().create(config);
	out->info = source->info();
	out->frames.resize(config.sim.frames);
	const double cpu0 = process_cpu_s();
	for (auto &frame : out->frames) {
		frame.allocate(out->info.geometry);
		if (source->grab(frame) != drivers::GrabStatus::Frame)
			throw std::runtime_error("the sim ended early");
	}
	out->render_cpu_ms = (process_cpu_s() - cpu0) * 1e3 / static_cast<double>(out->frames.size());
	out->info.live = true;
	return out;
}

/// Plays pre-rendered frames at their frame rate, copying each into the pool's frame as a camera driver
/// copies its buffer: what the pipeline sees is the live sim's, without the renderer on the same cores.
class PrerenderedSource final : public drivers::FrameSource
{
public:
	explicit PrerenderedSource(std::shared_ptr<const RenderedFrames> frames) : frames_(std::move(frames)) {}
	const drivers::SourceInfo &info() const override { return frames_->info; }
	drivers::GrabStatus grab(StereoFrame &into) override
	{
		if (next_ >= frames_->frames.size())
			return drivers::GrabStatus::EndOfStream;
		const StereoFrame &from = frames_->frames[next_];
		pacer_.wait_for(from.device_ns);
		from.copy_to(into);
		into.host_ns = monotonic_ns(); // complete on the host now, as a camera's frame would be
		++next_;
		return drivers::GrabStatus::Frame;
	}

private:
	std::shared_ptr<const RenderedFrames> frames_;
	drivers::Pacer pacer_{drivers::ReplayRate::Recorded}; ///< at the frames' own spacing, like a replay
	size_t next_ = 0;
};

struct Run {
	protocol::LatencySummary latency;
	double fps = 0;
	double cpu_ms = 0;	 ///< process CPU per published frame, every thread (the sim's rendering too when live)
	double first_max_ms = 0; ///< the largest latency of the first 10 frames published
	daemon::PipelineStats stats;
	std::map<std::string, double> stage_ms; ///< mean per published frame
	std::optional<daemon::DdsPublisher::Stats> dds;
	uint64_t received = 0; ///< samples the subscriber took
};

enum class Path { Spine, Mono, Stereo };
enum class Publish { None, Ndjson, Dds, DdsSubscribed };

/// A subscriber in a participant of its own, taking every sample of the three frame topics as they come.
class Subscriber
{
public:
	explicit Subscriber(const std::string &name)
	{
		participant_ = dds_create_participant(0, nullptr, nullptr);
		const auto reader = [&](const dds_topic_descriptor_t *type, const std::string &topic) {
			const dds_entity_t t = dds_create_topic(participant_, type, topic.c_str(), nullptr, nullptr);
			dds_qos_t *qos = dds_create_qos();
			dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
			dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
			readers_.push_back(dds_create_reader(participant_, t, qos, nullptr));
			dds_delete_qos(qos);
		};
		reader(&nav_msgs_msg_dds__Odometry__desc, "rt/stereod/" + name + "/odom");
		reader(&sensor_msgs_msg_dds__PointCloud2__desc, "rt/stereod/" + name + "/points");
		reader(&vision_msgs_msg_dds__Detection3DArray__desc, "rt/stereod/" + name + "/groups");
		thread_ = std::thread([this] {
			void *samples[16] = {};
			dds_sample_info_t infos[16];
			while (!stop_.load()) {
				for (const dds_entity_t r : readers_) {
					const int n = dds_take(r, samples, infos, 16, 16);
					if (n > 0) {
						received_ += static_cast<uint64_t>(n);
						dds_return_loan(r, samples, n);
					}
				}
				std::this_thread::sleep_for(std::chrono::milliseconds(2));
			}
		});
	}
	~Subscriber()
	{
		stop_.store(true);
		thread_.join();
		dds_delete(participant_);
	}
	[[nodiscard]] uint64_t received() const { return received_; }

private:
	dds_entity_t participant_;
	std::vector<dds_entity_t> readers_;
	std::atomic<bool> stop_{false};
	std::atomic<uint64_t> received_{0};
	std::thread thread_;
};

/// What every run shares: where the frames come from (the sim rendering live, or the pre-rendered frames when
/// given) and the ring they wait in.
struct Setup {
	drivers::SourceConfig config;
	std::shared_ptr<const RenderedFrames> rendered;
	size_t ring_capacity = daemon::PipelineOptions{}.ring_capacity;
	bool warm_up = daemon::PipelineOptions{}.warm_up;
};

Run run(const Setup &setup, Path path, double seconds, size_t workers, Publish publish = Publish::None,
	vision::GroupFlow flow = vision::GroupFlow::Sparse, const vision::StereoParams &stereo = {},
	const vision::MatchParams &matching = {}, const vision::FeatureParams &features = {})
{
	std::unique_ptr<daemon::DdsPublisher> dds;
	std::unique_ptr<Subscriber> subscriber;
	if (publish == Publish::Dds || publish == Publish::DdsSubscribed) {
		daemon::DdsConfig c;
		c.enabled = true;
		c.name = "bench";
		dds = std::make_unique<daemon::DdsPublisher>(c);
	}
	if (publish == Publish::DdsSubscribed)
		subscriber = std::make_unique<Subscriber>("bench");
	std::string message; // built as the daemon builds it: the cost being compared
	std::unique_ptr<drivers::FrameSource> source;
	if (setup.rendered)
		source = std::make_unique<PrerenderedSource>(setup.rendered);
	else
		source = drivers::SourceRegistry::with_builtin_drivers().create(setup.config);
	daemon::PipelineOptions options;
	options.workers = workers;
	options.ring_capacity = setup.ring_capacity;
	options.overflow = OverflowPolicy::DropOldest;
	options.motion.enabled = path != Path::Spine;
	if (path == Path::Stereo)
		options.motion.rig = source->info().calibration; // both eyes' features, stereo, pose, geometric check
	options.motion.dense.method = flow; // the groups' members: feature matches, or seed 002's global flow
	options.motion.stereo = stereo;
	options.motion.matching = matching;
	options.motion.features = features;
	options.warm_up = setup.warm_up;
	std::mutex m;
	std::vector<int64_t> latencies;
	std::map<std::string, double> stages;
	daemon::Pipeline pipeline(std::move(source), options, [&](FrameResult &r) {
		if (publish != Publish::None) { // what the daemon's publisher does with each result
			message = protocol::frame_message(r);
			if (dds)
				dds->offer(r);
		}
		std::lock_guard lock(m);
		latencies.push_back(r.t_publish_ns - r.t_host_ns);
		for (const auto &t : r.timing)
			stages[t.name] += t.ms;
	});
	const double cpu0 = process_cpu_s();
	pipeline.start();
	std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
	pipeline.request_stop();
	pipeline.wait();
	const double cpu_s = process_cpu_s() - cpu0;
	Run out;
	out.stats = pipeline.stats();
	out.latency = summarize_ns(latencies);
	for (size_t i = 0; i < std::min<size_t>(10, latencies.size()); ++i)
		out.first_max_ms = std::max(out.first_max_ms, static_cast<double>(latencies[i]) * 1e-6);
	out.fps = static_cast<double>(latencies.size()) / seconds;
	out.cpu_ms = cpu_s * 1e3 / std::max<double>(1, static_cast<double>(latencies.size()));
	const double n = std::max<double>(1, static_cast<double>(latencies.size()));
	for (const auto &[name, ms] : stages)
		out.stage_ms[name] = ms / n;
	if (dds)
		out.dds = dds->stats();
	if (subscriber)
		out.received = subscriber->received();
	return out;
}

void row(const char *name, const Run &r)
{
	const auto stage = [&](const char *key) {
		const auto it = r.stage_ms.find(key);
		return it == r.stage_ms.end() ? 0.0 : it->second;
	};
	std::printf("| %-28s | %6.1f | %6.1f | %7.2f | %7.2f | %7.2f | %7.2f | %7.2f | %6llu | %6llu | %6.2f | %6.2f | "
		    "%6.2f | %6.2f | %6.2f | %6.2f | %6.2f |\n",
		    name, r.fps, r.cpu_ms, r.latency.p50_ms, r.latency.p90_ms, r.latency.p99_ms, r.latency.max_ms,
		    r.first_max_ms, static_cast<unsigned long long>(r.stats.ring_evicted),
		    static_cast<unsigned long long>(r.stats.pool_exhausted), stage("extract"), stage("stereo"),
		    stage("match") + stage("subpixel"), stage("classify"), stage("pose"),
		    stage("flow_image") + stage("flow"), stage("groups"));
}

} // namespace

int main(int argc, char **argv)
{
	CLI::App app{"capture-to-publish latency on the live sim"};
	double seconds = 20;
	int width = 1024, height = 768;
	double fps = 30;
	size_t workers = daemon::default_workers();
	std::string scene = "default";
	app.add_option("-t,--seconds", seconds, "seconds per run");
	app.add_option("--width", width);
	app.add_option("--height", height);
	app.add_option("--fps", fps);
	app.add_option("--workers", workers);
	app.add_option("--scene", scene);
	bool with_flow = false;
	app.add_flag("--flow", with_flow, "also the stereo path with the groups on seed 002's global flow (lk, dis)");
	bool with_dds = false;
	app.add_flag("--dds", with_dds, "also the stereo path publishing NDJSON, NDJSON + DDS, and with a subscriber");
	size_t ring = daemon::PipelineOptions{}.ring_capacity;
	app.add_option("--ring", ring, "frames queued between capture and processing (pipeline.ring_capacity)")
		->check(CLI::Range(1, 1024));
	bool default_only = false;
	app.add_flag("--default-only", default_only, "only the stereo path as configured by default");
	int follow_lost_pairs = 0;
	app.add_option("--follow-lost-pairs", follow_lost_pairs,
		       "only the default stereo path, N times with matching.follow_lost on (the default) and off in "
		       "turn, to compare the two on a noisy machine")
		->check(CLI::Range(1, 100));
	int candidate_pairs = 0;
	app.add_option("--candidate-pairs", candidate_pairs,
		       "only the default stereo path, N times with features.candidate_selection per_cell (the default) "
		       "and whole_image in turn")
		->check(CLI::Range(1, 100));
	int fast_pass_pairs = 0;
	app.add_option("--fast-pass-pairs", fast_pass_pairs,
		       "only the default stereo path, N times with ORB's first FAST pass at a high threshold (the "
		       "default) and with one pass at the configured threshold in turn (the same keypoints)")
		->check(CLI::Range(1, 100));
	bool cold = false;
	app.add_flag("--cold", cold,
		     "every run without the workers' warm-up (PipelineOptions::warm_up), to compare its first frames");
	bool prerendered = false;
	app.add_flag("--prerendered", prerendered,
		     "render the sim's frames before the runs and play them at the frame rate (needs about 5 MB of "
		     "memory per frame at 1024x768: 2.5 GB for 15 s)");
	CLI11_PARSE(app, argc, argv);
	spdlog::set_level(spdlog::level::warn);

	Setup config;
	config.config.realtime = true;
	config.config.sim.width = width;
	config.config.sim.height = height;
	config.config.sim.fps = fps;
	config.config.sim.scene = scene;
	config.ring_capacity = ring;
	config.warm_up = !cold;
	std::printf("sim '%s' %dx%d stereo at %.0f fps, %zu workers, ring of %zu, %.0f s per run, drop-oldest, %s\n",
		    scene.c_str(), width, height, fps, workers, ring, seconds,
		    cold ? "workers not warmed up (--cold)" : "workers warmed up before capture");
	if (prerendered) {
		config.rendered = prerender(config.config, seconds);
		std::printf("frames pre-rendered and played at %.0f fps (rendering them took %.1f ms of CPU a frame, "
			    "%zu frames)\n",
			    fps, config.rendered->render_cpu_ms, config.rendered->frames.size());
	} else {
		std::printf("frames rendered live by the sim on the same cores (--prerendered to leave it out)\n");
	}
	std::printf("\n| %-28s | %6s | %6s | %7s | %7s | %7s | %7s | %7s | %6s | %6s | %6s | %6s | %6s | %6s | %6s | "
		    "%6s | %6s |\n",
		    "pipeline", "fps", "CPU ms", "p50 ms", "p90 ms", "p99 ms", "max ms", "1st 10", "ring", "pool",
		    "extr.", "stereo", "match", "class.", "pose", "flow", "groups");
	std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
	// The default stereo path and one variant in turn, `pairs` times, so a noisy machine's spells fall on both.
	const auto alternate = [&](int pairs, const char *variant, const vision::MatchParams &matching,
				   const vision::FeatureParams &features) {
		for (int i = 0; i < pairs; ++i) {
			row("stereo + pose (default)", run(config, Path::Stereo, seconds, workers));
			row(variant, run(config, Path::Stereo, seconds, workers, Publish::None,
					 vision::GroupFlow::Sparse, {}, matching, features));
		}
	};
	vision::MatchParams no_follow_lost;
	no_follow_lost.follow_lost = false;
	if (follow_lost_pairs > 0) {
		alternate(follow_lost_pairs, "stereo + pose, no follow_lost", no_follow_lost, {});
		return 0;
	}
	if (candidate_pairs > 0) {
		vision::FeatureParams whole_image;
		whole_image.candidate_selection = vision::CandidateSelection::WholeImage;
		alternate(candidate_pairs, "stereo + pose, whole_image", {}, whole_image);
		return 0;
	}
	if (fast_pass_pairs > 0) {
		vision::FeatureParams one_pass;
		one_pass.orb_fast_first_pass_threshold = 0;
		alternate(fast_pass_pairs, "stereo + pose, one FAST pass", {}, one_pass);
		return 0;
	}
	if (default_only) {
		row("stereo + pose (default)", run(config, Path::Stereo, seconds, workers));
		return 0;
	}
	row("spine only (vision off)", run(config, Path::Spine, seconds, workers));
	row("ORB + seed-000 (left eye)", run(config, Path::Mono, seconds, workers));
	row("stereo + pose (default)", run(config, Path::Stereo, seconds, workers));
	// The stereo stage's other ways (docs/geometry.md): the right eye's features every frame before the row
	// search (the default until stop 33), seed 002's descriptor matching alone, and the row search without
	// the health frames' descriptor matching.
	vision::StereoParams both_every_frame, descriptors_only, rows_only;
	both_every_frame.right_features = true;
	descriptors_only.right_features = true;
	descriptors_only.row_search = false;
	rows_only.health_every_frames = 0;
	row("stereo, right features + rows",
	    run(config, Path::Stereo, seconds, workers, Publish::None, vision::GroupFlow::Sparse, both_every_frame));
	row("stereo, descriptors only",
	    run(config, Path::Stereo, seconds, workers, Publish::None, vision::GroupFlow::Sparse, descriptors_only));
	row("stereo, rows, no health frame",
	    run(config, Path::Stereo, seconds, workers, Publish::None, vision::GroupFlow::Sparse, rows_only));
	// The temporal matches the descriptors refused, found again by Lucas-Kanade (matching.rescue, on by
	// default; its cost is in the match column).
	vision::MatchParams no_rescue;
	no_rescue.rescue = false;
	row("stereo + pose, no rescue",
	    run(config, Path::Stereo, seconds, workers, Publish::None, vision::GroupFlow::Sparse, {}, no_rescue));
	// Corners the detector loses, kept where Lucas-Kanade follows them (matching.follow_lost, on by default;
	// in the match column too).
	row("stereo + pose, no follow_lost",
	    run(config, Path::Stereo, seconds, workers, Publish::None, vision::GroupFlow::Sparse, {}, no_follow_lost));
	if (with_flow) {
		row("stereo, groups.flow = lk",
		    run(config, Path::Stereo, seconds, workers, Publish::None, vision::GroupFlow::PyrLk));
		row("stereo, groups.flow = dis",
		    run(config, Path::Stereo, seconds, workers, Publish::None, vision::GroupFlow::Dis));
	}
	std::vector<std::pair<const char *, Run>> dds_rows;
	if (with_dds) {
		for (const auto &[name, publish] :
		     {std::pair{"stereo + NDJSON (DDS off)", Publish::Ndjson},
		      std::pair{"stereo + NDJSON + DDS", Publish::Dds},
		      std::pair{"stereo + NDJSON + DDS, 1 sub", Publish::DdsSubscribed}}) {
			dds_rows.emplace_back(name, run(config, Path::Stereo, seconds, workers, publish));
			row(name, dds_rows.back().second);
		}
	}
	std::printf("\nlatency = t_publish - t_host (capture complete on the host -> message handed to the socket);\n"
		    "1st 10 = the largest latency of the first 10 frames; ring/pool = frames dropped by drop-oldest / "
		    "for want of a free frame; stage columns: mean ms per "
		    "frame (flow: the image scaling and the dense flow).\n");
	for (const auto &[name, r] : dds_rows)
		if (r.dds)
			std::printf("%s: DDS publishing %.3f ms mean, %.3f ms max per frame (3 messages, on the "
				    "publisher's "
				    "own thread); %llu frames published, %llu dropped, %llu samples taken by the "
				    "subscriber\n",
				    name, r.dds->publish_ms_mean, r.dds->publish_ms_max,
				    static_cast<unsigned long long>(r.dds->frames_published),
				    static_cast<unsigned long long>(r.dds->frames_dropped),
				    static_cast<unsigned long long>(r.received));
	if (dds_rows.size() == 3)
		std::printf("p99 with DDS / without: %.2f (no subscriber), %.2f (one subscriber)\n",
			    dds_rows[1].second.latency.p99_ms / dds_rows[0].second.latency.p99_ms,
			    dds_rows[2].second.latency.p99_ms / dds_rows[0].second.latency.p99_ms);
	return 0;
}
