// stereoctl: watch the daemon, record and inspect recordings, evaluate and render results.
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <thread>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "core/clock.hpp"
#include "core/protocol.hpp"
#include "daemon/socket_server.hpp"
#include "drivers/replay/mcap_recording.hpp"
#include "tools/common.hpp"
#include "tools/evaluation.hpp"
#include "tools/group_eval.hpp"
#include "tools/subcommands.hpp"

using namespace stereod;
namespace fs = std::filesystem;

namespace {

volatile std::sig_atomic_t g_interrupted = 0; // set by SIGINT/SIGTERM in record and watch

void on_signal(int)
{
	g_interrupted = 1;
}

/// SIGINT/SIGTERM set g_interrupted and interrupt a blocking wait: std::signal installs handlers with
/// SA_RESTART, under which `stereoctl watch` ignored Ctrl-C until data arrived.
void catch_interrupts()
{
	struct sigaction action {
	};
	action.sa_handler = on_signal;
	sigemptyset(&action.sa_mask);
	action.sa_flags = 0; // no SA_RESTART
	::sigaction(SIGINT, &action, nullptr);
	::sigaction(SIGTERM, &action, nullptr);
}

void add_source_options(CLI::App &cmd, tools::SourceOptions &options)
{
	cmd.add_option("-c,--config", options.config_path, "stereod config file");
	cmd.add_option("-s,--set", options.overrides, "override: section.key=value (repeatable)")
		->allow_extra_args(false);
	cmd.add_option("-i,--input", options.input,
		       "recording, dataset folder or video (default: the config's source)");
	cmd.add_option("-f,--format", options.format, "auto | recording | video | kitti | euroc | tum | folder | sim");
}

// ---------------------------------------------------------------------------------------------- watch
int watch(const std::string &socket_path, bool raw, long max_frames, double timeout_s)
{
	const sockaddr_un addr = daemon::unix_socket_address(socket_path);
	const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (::connect(fd, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)) != 0) {
		std::cerr << "stereoctl watch: cannot connect to " << socket_path << ": " << std::strerror(errno)
			  << " (is stereod running? see output.socket)\n";
		return 1;
	}
	const timespec limit{
		static_cast<time_t>(timeout_s),
		static_cast<long>((timeout_s - static_cast<double>(static_cast<time_t>(timeout_s))) * 1e9)};
	// SIGINT and SIGTERM stay blocked but inside ppoll(), which lets them in only while it waits: one that
	// comes between the check of g_interrupted and the wait is then taken by the wait (it returns EINTR)
	// instead of being spent before it, which left a blocking recv() waiting for data that never came.
	sigset_t interrupts, while_waiting;
	sigemptyset(&interrupts);
	sigaddset(&interrupts, SIGINT);
	sigaddset(&interrupts, SIGTERM);
	::sigprocmask(SIG_BLOCK, &interrupts, &while_waiting);
	sigdelset(&while_waiting, SIGINT);
	sigdelset(&while_waiting, SIGTERM);
	std::string buffer;
	char chunk[65536];
	long frames = 0;
	while (!g_interrupted) {
		pollfd readable{fd, POLLIN, 0};
		const int ready = ::ppoll(&readable, 1, timeout_s > 0 ? &limit : nullptr, &while_waiting);
		if (ready < 0 && errno == EINTR)
			continue; // g_interrupted says whether it was ours
		if (ready <= 0)
			break; // the timeout (--timeout), or an error
		const ssize_t n = ::recv(fd, chunk, sizeof(chunk), 0);
		if (n <= 0)
			break;
		buffer.append(chunk, static_cast<size_t>(n));
		size_t start = 0, end = 0;
		while ((end = buffer.find('\n', start)) != std::string::npos) {
			const std::string line = buffer.substr(start, end - start);
			start = end + 1;
			if (raw) {
				std::cout << line << '\n';
			} else {
				const auto m = nlohmann::json::parse(line, nullptr, false);
				const std::string type = m.is_object() ? m.value("type", "?") : "?";
				if (type == "frame") {
					int s = 0, d = 0, u = 0;
					for (const auto &p : m["points"]) {
						const auto label = p["label"].get<std::string>();
						(label == "static" ? s : label == "dynamic" ? d : u)++;
					}
					const double latency = static_cast<double>(m["t_publish_ns"].get<int64_t>() -
										   m["t_host_ns"].get<int64_t>()) *
							       1e-6;
					std::cout << "frame " << m["seq"] << "  t "
						  << m["t_capture_ns"].get<int64_t>() / 1000000 << " ms  "
						  << m["status"].get<std::string>() << "  points " << s << " static "
						  << d << " dynamic " << u << " uncertain  latency " << latency
						  << " ms  timing " << m["timing_ms"].dump() << '\n';
				} else if (type == "status") {
					std::cout << "status  fps " << m["fps"].dump() << "  drops "
						  << m["drops"].dump() << "  latency "
						  << m["latency_ms"]["capture_to_publish"].dump() << "  clients "
						  << m["clients"] << '\n';
				} else {
					std::cout << line << '\n';
				}
			}
			if (line.find("\"type\":\"frame\"") != std::string::npos && max_frames > 0 &&
			    ++frames >= max_frames) {
				std::cout.flush();
				::close(fd);
				return 0;
			}
		}
		buffer.erase(0, start);
		std::cout.flush();
	}
	::close(fd);
	return max_frames > 0 && frames < max_frames ? 1 : 0;
}

// --------------------------------------------------------------------------------------------- record
int record(const tools::SourceOptions &options, const std::string &output, uint64_t max_frames, double seconds,
	   bool sync, bool images)
{
	auto source = tools::open_source(options);
	const auto &info = source->info();
	StereoFrame frame;
	frame.allocate(info.geometry);
	if (images && !drivers::is_mcap_path(output))
		throw std::runtime_error("--images: only MCAP recordings (.mcap) carry JPEG images");
	drivers::RecorderOptions recorder_options;
	recorder_options.images = images;
	const auto writer = drivers::open_recorder(
		output, drivers::RecordingHeader::stamped_now(info.name, info.description, info.geometry),
		recorder_options);
	catch_interrupts();
	const int64_t start = monotonic_ns();
	while (!g_interrupted) {
		if (max_frames > 0 && writer->frames_written() >= max_frames)
			break;
		if (seconds > 0 && static_cast<double>(monotonic_ns() - start) * 1e-9 >= seconds)
			break;
		const auto status = source->grab(frame);
		if (status == drivers::GrabStatus::EndOfStream)
			break;
		if (status == drivers::GrabStatus::Lost) {
			// A camera went away: keep trying, as the daemon does, until it is back or we are stopped.
			std::cerr << "stereoctl record: source lost; reconnecting\n";
			while (!g_interrupted && !source->reconnect())
				std::this_thread::sleep_for(std::chrono::milliseconds(500));
			continue;
		}
		if (status != drivers::GrabStatus::Frame)
			continue;
		writer->append(frame, sync);
	}
	writer->finish();
	std::cerr << "stereoctl record: " << writer->frames_written() << " frames, " << writer->bytes_written()
		  << " bytes to " << output << "\n";
	return 0;
}

// ----------------------------------------------------------------------------------------------- eval
/// Loads the mask for `seq` from a truth folder (truth.ndjson's "mask" paths, or <seq>.png / %06d.png).
cv::Mat load_mask(const fs::path &dir, uint64_t seq)
{
	char padded[32];
	std::snprintf(padded, sizeof(padded), "%06llu.png", static_cast<unsigned long long>(seq));
	for (const fs::path &candidate : {dir / "masks" / padded, dir / padded, dir / (std::to_string(seq) + ".png")})
		if (fs::exists(candidate))
			return cv::imread(candidate.string(), cv::IMREAD_GRAYSCALE);
	return {};
}

/// Which movers of a pixels-only reference walk (tools::mark_walking): against its masks `frames` before and
/// after, a move of at least `min_move_px`.
struct WalkingRule {
	int frames = 5;
	double min_move_px = 5;
};

/// Moving-target groups against the truth's movers (tools/group_eval.hpp).
int eval_groups(const std::string &results_path, const std::string &truth_dir, const std::string &name, bool json_out,
		bool count_detail, const WalkingRule &walking)
{
	std::map<uint64_t, nlohmann::json> truth_lines;
	{
		std::ifstream in(fs::path(truth_dir) / "truth.ndjson");
		if (!in) {
			std::cerr << "stereoctl eval --groups: " << truth_dir << "/truth.ndjson: cannot read\n";
			return 1;
		}
		std::string line;
		while (std::getline(in, line))
			if (!line.empty()) {
				nlohmann::json truth = nlohmann::json::parse(line);
				const auto seq = truth.at("seq").get<uint64_t>();
				truth_lines[seq] = std::move(truth);
			}
	}
	tools::GroupScore score;
	// A mover counts as in view from 400 pixels on (a person 20 x 20 px): smaller ones carry too few
	// features to be grouped at all.
	constexpr int kMinPixels = 400;
	// Each mask is read once, though it is looked at from the frames before and after it too.
	std::map<uint64_t, cv::Mat> masks;
	const auto mask_at = [&](uint64_t seq) -> const cv::Mat & {
		auto it = masks.find(seq);
		if (it == masks.end())
			it = masks.emplace(seq, load_mask(truth_dir, seq)).first;
		return it->second;
	};
	const auto span = static_cast<uint64_t>(std::max(walking.frames, 0));
	for (const auto &[seq, result] : tools::read_results(results_path)) {
		const auto truth = truth_lines.find(seq);
		const cv::Mat mask = mask_at(seq);
		if (truth == truth_lines.end() || mask.empty())
			continue;
		std::vector<tools::TrueMover> movers = tools::visible_movers(mask, truth->second, kMinPixels);
		if (span > 0)
			tools::mark_walking(movers, mask, seq >= span ? mask_at(seq - span) : cv::Mat(),
					    mask_at(seq + span), walking.min_move_px);
		score.add(result, mask, movers);
		std::erase_if(masks, [&](const auto &entry) { return entry.first + span < seq; });
	}
	if (score.frames == 0) {
		std::cerr << "stereoctl eval --groups: no frame of " << results_path << " has truth in " << truth_dir
			  << "\n";
		return 1;
	}
	if (json_out) {
		const auto ratio = [](uint64_t a, uint64_t b) {
			return b > 0 ? static_cast<double>(a) / static_cast<double>(b) : 0.0;
		};
		std::cout
			<< nlohmann::json{{"name", name},
					  {"frames", score.frames},
					  {"frames_separated", score.frames_separated},
					  {"count_exact", ratio(score.count_exact, score.frames_separated)},
					  {"groups", score.groups},
					  {"groups_on_movers", ratio(score.groups_on_movers, score.groups)},
					  {"groups_without_movers", score.groups_without_movers},
					  {"movers_covered", ratio(score.movers_covered, score.mover_views)},
					  {"movers_inside", ratio(score.movers_inside, score.mover_views)},
					  {"movers_untouched", ratio(score.movers_untouched, score.mover_views)},
					  {"centroid_error_m", tools::median(score.centroid_error_m)},
					  {"speed_relative_error", tools::median(score.speed_relative_error)},
					  {"speed_within_10_percent",
					   tools::fraction_below(score.speed_relative_error, 0.1)},
					  {"speed_within_1_sigma", tools::fraction_below(score.speed_error_sigmas, 1)},
					  {"speed_within_2_sigma", tools::fraction_below(score.speed_error_sigmas, 2)},
					  {"heading_error_deg", tools::median(score.heading_error_deg)},
					  {"heading_within_15_deg", tools::fraction_below(score.heading_error_deg, 15)},
					  {"id_switches", score.id_switches},
					  {"walking_views", score.walking_views},
					  {"walking_covered", ratio(score.walking_covered, score.walking_views)},
					  {"walking_label_precision", score.walking_labels.precision()},
					  {"walking_label_recall", score.walking_labels.recall()},
					  {"walking_label_f1", score.walking_labels.f1()},
					  {"count_too_many", ratio(score.count_over, score.frames_separated)},
					  {"count_too_few", ratio(score.count_under, score.frames_separated)},
					  {"frames_every_mover_seen", score.frames_seen},
					  {"count_exact_every_mover_seen",
					   ratio(score.count_exact_seen, score.frames_seen)},
					  {"movers_split",
					   ratio(score.separated_movers_split, score.separated_mover_views)},
					  {"movers_missed",
					   ratio(score.separated_movers_missed, score.separated_mover_views)},
					  {"groups_off_movers",
					   ratio(score.separated_groups_off, score.separated_groups)}}
				   .dump()
			<< "\n";
	} else {
		std::cout << "\n" << tools::group_score_table(name, score);
		if (count_detail) {
			std::cout << "\n" << tools::group_count_table(name, score);
			if (!score.by_mover.empty())
				std::cout << "\n" << tools::group_mover_table(score);
		}
	}
	return 0;
}

int eval(const std::string &results_path, const std::string &truth_dir, const std::string &name, int border_px,
	 double min_coverage, const std::string &per_frame_csv, bool json_out, bool per_mover,
	 const std::string &errors_csv)
{
	const auto results = tools::read_results(results_path);
	tools::LabelScore all, covered;
	tools::DepthScore depth;
	tools::PriorRegionScore regions;
	std::map<int, tools::MoverCounts> movers;
	uint64_t missing = 0;
	std::ofstream csv;
	if (!per_frame_csv.empty()) {
		csv.open(per_frame_csv);
		csv << "seq,static,dynamic,uncertain,precision,recall,f1,static_error_rate,coverage\n";
	}
	std::ofstream errors;
	if (!errors_csv.empty()) {
		errors.open(errors_csv);
		errors << tools::label_errors_header() << '\n';
	}
	for (const auto &[seq, result] : results) {
		if (result.points.empty())
			continue; // the first frame has nothing to pair with
		const cv::Mat mask = load_mask(truth_dir, seq);
		if (mask.empty()) {
			++missing;
			continue;
		}
		const auto score = tools::score_frame(result, mask, border_px);
		char depth_name[32];
		std::snprintf(depth_name, sizeof(depth_name), "%06llu.png", static_cast<unsigned long long>(seq));
		cv::Mat depth_mm;
		if (const fs::path depth_file = fs::path(truth_dir) / "depth" / depth_name; fs::exists(depth_file)) {
			depth_mm = cv::imread(depth_file.string(), cv::IMREAD_ANYDEPTH);
			depth += tools::score_depth(result, depth_mm);
		}
		if (errors)
			tools::write_label_errors(errors, seq, result, mask, depth_mm);
		if (per_mover)
			tools::count_per_mover(result, mask, movers);
		regions += tools::score_prior_regions(result, mask);
		all += score;
		if (score.mean_coverage() >= min_coverage)
			covered += score;
		if (csv)
			csv << seq << ',' << score.static_true + score.static_false << ','
			    << score.dynamic_true + score.dynamic_false << ','
			    << score.uncertain_on_mover + score.uncertain_on_scene << ',' << score.precision() << ','
			    << score.recall() << ',' << score.f1() << ',' << score.static_error_rate() << ','
			    << score.mean_coverage() << '\n';
	}
	if (all.frames == 0) {
		std::cerr << "stereoctl eval: no frame of " << results_path << " has a mask in " << truth_dir << "\n";
		return 1;
	}
	if (json_out) {
		auto row = [](const tools::LabelScore &s) {
			return nlohmann::json{{"frames", s.frames},
					      {"precision", s.precision()},
					      {"recall", s.recall()},
					      {"f1", s.f1()},
					      {"static_error_rate", s.static_error_rate()},
					      {"uncertain_rate", s.uncertain_rate()},
					      {"uncertain_on_movers", s.uncertain_on_mover},
					      {"uncertain_on_scene", s.uncertain_on_scene},
					      {"mean_coverage", s.mean_coverage()}};
		};
		std::cout << nlohmann::json{{"name", name},
					    {"all", row(all)},
					    {"covered", row(covered)},
					    {"min_coverage", min_coverage},
					    {"frames_without_mask", missing},
					    {"depth",
					     {{"points", depth.points},
					      {"with_depth", depth.with_depth},
					      {"scored", depth.relative_errors.size()},
					      {"median_relative_error", depth.median()},
					      {"within_1_percent", depth.fraction_within(0.01)},
					      {"within_5_percent", depth.fraction_within(0.05)}}}}
				     .dump()
			  << "\n";
		return 0;
	}
	std::cout << tools::score_table_header() << "\n"
		  << tools::format_score_row(name + " (all frames)", all) << "\n"
		  << tools::format_score_row(
			     name + " (movers >= " + std::to_string(static_cast<int>(min_coverage * 100)) + "%)",
			     covered)
		  << "\n";
	if (per_mover) {
		std::cout << "\n| mover (mask id) | dynamic | static | uncertain | recall |\n|---|---|---|---|---|\n";
		for (const auto &[id, c] : movers)
			std::cout << "| " << id << " | " << c.dynamic << " | " << c.static_ << " | " << c.uncertain
				  << " | " << std::fixed << std::setprecision(3) << c.recall() << " |\n";
	}
	if (!depth.relative_errors.empty())
		std::cout << "\ndepth: " << depth.with_depth << " of " << depth.points << " points carry xyz_m ("
			  << std::fixed << std::setprecision(1)
			  << 100.0 * static_cast<double>(depth.with_depth) /
				     static_cast<double>(std::max<uint64_t>(depth.points, 1))
			  << "%); against the true depth: median relative error " << std::setprecision(3)
			  << 100 * depth.median() << "%, within 1%: " << std::setprecision(1)
			  << 100 * depth.fraction_within(0.01) << "%, within 5%: " << 100 * depth.fraction_within(0.05)
			  << "%\n";
	if (regions.detected + regions.carried > 0)
		std::cout << "\nperson prior: " << regions.detected_on_mover << " of " << regions.detected
			  << " detected regions on a mover (>= 10% of the box), " << regions.carried_on_mover << " of "
			  << regions.carried << " carried ones\n";
	if (missing)
		std::cerr << "stereoctl eval: " << missing << " frames had no mask\n";
	return 0;
}

// --------------------------------------------------------------------------------------------- render
const cv::Scalar kStatic(255, 80, 0), kDynamic(0, 0, 255), kUncertain(0, 210, 255);

void draw_points(cv::Mat &image, const FrameResult &result, bool arrows)
{
	for (const auto &p : result.points) {
		const cv::Point2f at(p.u, p.v);
		const cv::Scalar colour = p.label == PointLabel::Static	   ? kStatic
					  : p.label == PointLabel::Dynamic ? kDynamic
									   : kUncertain;
		if (arrows && p.label != PointLabel::Uncertain)
			cv::line(image, cv::Point2f(p.prev_u, p.prev_v), at, colour, 1, cv::LINE_AA);
		const int radius = p.label == PointLabel::Uncertain ? 2 : 4;
		cv::circle(image, at, radius, colour, p.label == PointLabel::Uncertain ? 1 : cv::FILLED, cv::LINE_AA);
	}
	// Groups: box and id in a colour of their own (stable per id), the image velocity as an arrow from the
	// box's centre (the motion over half a second), and the speed where it was measured. A coasted group (not
	// found in this frame, carried on by its velocity) has a thin box and a "+N" for the frames missed.
	for (const auto &g : result.groups) {
		const cv::Scalar colour((g.id * 67) % 200 + 55, (g.id * 151) % 200 + 55, 40);
		const cv::Point2f a(g.box_px[0], g.box_px[1]), b(g.box_px[2], g.box_px[3]);
		cv::rectangle(image, a, b, colour, g.missed_frames > 0 ? 1 : 2, cv::LINE_AA);
		const cv::Point2f centre = (a + b) * 0.5f;
		const cv::Point2f velocity(static_cast<float>(g.image_velocity_pxps[0]),
					   static_cast<float>(g.image_velocity_pxps[1]));
		cv::arrowedLine(image, centre, centre + velocity * 0.5f, colour, 2, cv::LINE_AA, 0, 0.25);
		std::string label = "#" + std::to_string(g.id);
		if (g.missed_frames > 0)
			label += " +" + std::to_string(g.missed_frames);
		if (g.speed_mps) {
			char speed[48];
			if (g.speed_sigma_mps)
				std::snprintf(speed, sizeof speed, " %.1f +-%.1f m/s", *g.speed_mps,
					      *g.speed_sigma_mps);
			else
				std::snprintf(speed, sizeof speed, " %.1f m/s", *g.speed_mps);
			label += speed;
		}
		cv::putText(image, label, a + cv::Point2f(2, -4), cv::FONT_HERSHEY_SIMPLEX, 0.45, colour, 1,
			    cv::LINE_AA);
	}
	int s = 0, d = 0, u = 0;
	for (const auto &p : result.points)
		(p.label == PointLabel::Static ? s : p.label == PointLabel::Dynamic ? d : u)++;
	const std::string text = "seq " + std::to_string(result.seq) + "  static " + std::to_string(s) + "  dynamic " +
				 std::to_string(d) + "  uncertain " + std::to_string(u) + "  groups " +
				 std::to_string(result.groups.size());
	cv::rectangle(image, cv::Rect(0, 0, image.cols, 26), cv::Scalar(0, 0, 0), cv::FILLED);
	cv::putText(image, text, cv::Point(8, 18), cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(255, 255, 255), 1,
		    cv::LINE_AA);
}

/// Per-frame static/dynamic counts and stage times, like the seed's Figures 12-13.
cv::Mat plot(const std::map<uint64_t, FrameResult> &results)
{
	const int w = 1000, h = 640, margin = 60;
	cv::Mat canvas(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
	if (results.empty())
		return canvas;
	const double first = static_cast<double>(results.begin()->first);
	const double last = std::max(first + 1, static_cast<double>(results.rbegin()->first));
	int max_count = 1;
	double max_ms = 1;
	for (const auto &[seq, r] : results) {
		max_count = std::max(max_count, static_cast<int>(r.points.size()));
		for (const auto &t : r.timing)
			max_ms = std::max(max_ms, t.ms);
	}
	auto panel = [&](int top, int height, const char *title) {
		cv::rectangle(canvas, cv::Rect(margin, top, w - 2 * margin, height), cv::Scalar(0, 0, 0));
		cv::putText(canvas, title, cv::Point(margin, top - 8), cv::FONT_HERSHEY_SIMPLEX, 0.5,
			    cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
	};
	const int top1 = 40, height1 = 240, top2 = 340, height2 = 240;
	panel(top1, height1,
	      ("points per frame (max " + std::to_string(max_count) + "): blue static, red dynamic").c_str());
	panel(top2, height2,
	      ("stage time per frame, ms (max " + std::to_string(static_cast<int>(max_ms)) +
	       "): green extract, orange match, purple classify")
		      .c_str());
	auto x_of = [&](double seq) { return margin + (seq - first) / (last - first) * (w - 2 * margin); };
	std::map<std::string, cv::Scalar> stage_colour = {{"extract", cv::Scalar(0, 160, 0)},
							  {"match", cv::Scalar(0, 140, 255)},
							  {"classify", cv::Scalar(160, 0, 160)}};
	std::map<std::string, cv::Point2d> previous_stage;
	cv::Point2d prev_s, prev_d;
	bool have_prev = false;
	for (const auto &[seq, r] : results) {
		int s = 0, d = 0;
		for (const auto &p : r.points) {
			if (p.label == PointLabel::Static)
				++s;
			else if (p.label == PointLabel::Dynamic)
				++d;
		}
		const double x = x_of(static_cast<double>(seq));
		const cv::Point2d ps(x, top1 + height1 - static_cast<double>(s) / max_count * height1);
		const cv::Point2d pd(x, top1 + height1 - static_cast<double>(d) / max_count * height1);
		if (have_prev) {
			cv::line(canvas, prev_s, ps, kStatic, 1, cv::LINE_AA);
			cv::line(canvas, prev_d, pd, kDynamic, 1, cv::LINE_AA);
		}
		prev_s = ps, prev_d = pd, have_prev = true;
		for (const auto &t : r.timing) {
			const auto colour = stage_colour.find(t.name);
			if (colour == stage_colour.end())
				continue;
			const cv::Point2d pt(x, top2 + height2 - t.ms / max_ms * height2);
			if (auto it = previous_stage.find(t.name); it != previous_stage.end())
				cv::line(canvas, it->second, pt, colour->second, 1, cv::LINE_AA);
			previous_stage[t.name] = pt;
		}
	}
	cv::putText(canvas,
		    "frame " + std::to_string(static_cast<long>(first)) + " .. " +
			    std::to_string(static_cast<long>(last)),
		    cv::Point(margin, h - 20), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
	return canvas;
}

int render(const tools::SourceOptions &options, const std::string &results_path, const std::string &truth_dir,
	   const std::string &out_dir, const std::string &video_path, const std::string &sheet_path,
	   const std::vector<uint64_t> &sheet_frames, int every, bool arrows)
{
	const auto results =
		results_path.empty() ? std::map<uint64_t, FrameResult>{} : tools::read_results(results_path);
	auto source = tools::open_source(options);
	StereoFrame frame;
	frame.allocate(source->info().geometry);
	if (!out_dir.empty())
		fs::create_directories(out_dir);
	cv::VideoWriter video;
	std::vector<cv::Mat> sheet;
	cv::Mat canvas;
	uint64_t written = 0;
	while (source->grab(frame) == drivers::GrabStatus::Frame) {
		const bool want_file =
			!out_dir.empty() && every > 0 && frame.sequence % static_cast<uint64_t>(every) == 0;
		const bool want_sheet =
			std::find(sheet_frames.begin(), sheet_frames.end(), frame.sequence) != sheet_frames.end();
		if (!want_file && !want_sheet && video_path.empty())
			continue;
		if (frame.left.channels() == 1)
			cv::cvtColor(frame.left, canvas, cv::COLOR_GRAY2BGR);
		else
			frame.left.copyTo(canvas);
		if (!truth_dir.empty()) {
			// Movers from the ground truth, tinted green, to check labels by eye.
			const cv::Mat mask = load_mask(truth_dir, frame.sequence);
			if (!mask.empty()) {
				cv::Mat tinted;
				cv::addWeighted(canvas, 0.6,
						cv::Mat(canvas.size(), canvas.type(), cv::Scalar(0, 255, 0)), 0.4, 0,
						tinted);
				tinted.copyTo(canvas, mask);
			}
		}
		if (auto it = results.find(frame.sequence); it != results.end())
			draw_points(canvas, it->second, arrows);
		if (want_file) {
			char name[32];
			std::snprintf(name, sizeof(name), "%06llu.png",
				      static_cast<unsigned long long>(frame.sequence));
			cv::imwrite((fs::path(out_dir) / name).string(), canvas);
			++written;
		}
		if (want_sheet)
			sheet.push_back(canvas.clone());
		if (!video_path.empty()) {
			if (!video.isOpened()) {
				const double fps = source->info().geometry.nominal_fps > 0
							   ? source->info().geometry.nominal_fps
							   : 10;
				video.open(video_path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), fps, canvas.size());
				if (!video.isOpened())
					throw std::runtime_error(video_path + ": cannot write video");
			}
			video.write(canvas);
		}
	}
	if (!sheet_path.empty()) {
		if (sheet.empty())
			throw std::runtime_error("--sheet: none of the requested frames was found");
		const int cols = sheet.size() >= 4 ? 2 : 1;
		std::vector<cv::Mat> rows;
		for (size_t i = 0; i < sheet.size(); i += static_cast<size_t>(cols)) {
			std::vector<cv::Mat> row(sheet.begin() + static_cast<std::ptrdiff_t>(i),
						 sheet.begin() +
							 static_cast<std::ptrdiff_t>(std::min(sheet.size(), i + cols)));
			while (row.size() < static_cast<size_t>(cols))
				row.push_back(cv::Mat::zeros(sheet[0].size(), sheet[0].type()));
			cv::Mat joined;
			cv::hconcat(row, joined);
			rows.push_back(joined);
		}
		cv::Mat full;
		cv::vconcat(rows, full);
		if (full.cols > 1600)
			cv::resize(full, full, cv::Size(), 1600.0 / full.cols, 1600.0 / full.cols, cv::INTER_AREA);
		cv::imwrite(sheet_path, full);
		std::cerr << "stereoctl render: contact sheet of " << sheet.size() << " frames -> " << sheet_path
			  << "\n";
	}
	if (!out_dir.empty()) {
		cv::imwrite((fs::path(out_dir) / "plot.png").string(), plot(results));
		std::cerr << "stereoctl render: " << written << " frames and plot.png -> " << out_dir << "\n";
	}
	return 0;
}

} // namespace

int main(int argc, char **argv)
{
	CLI::App app{"stereoctl: watch stereod, record and inspect recordings, evaluate and render results"};
	app.require_subcommand(1);
	// Logs go to standard error: standard output may carry results (`process --output -`, `watch`).
	spdlog::set_default_logger(spdlog::stderr_color_mt("stereoctl"));
	spdlog::set_pattern("%Y-%m-%d %H:%M:%S.%e %^%l%$ %v");

	auto *watch_cmd = app.add_subcommand("watch", "print the messages stereod streams");
	std::string socket_path = "/tmp/stereod.sock";
	bool raw = false;
	long max_frames = 0;
	double timeout_s = 0;
	watch_cmd->add_option("-S,--socket", socket_path, "stereod's socket (output.socket)");
	watch_cmd->add_flag("--raw", raw, "print the JSON lines as they come");
	watch_cmd->add_option("-n,--count", max_frames, "exit after this many frame messages");
	watch_cmd->add_option("--timeout", timeout_s, "give up after this many seconds without data");

	auto *record_cmd = app.add_subcommand("record", "record any source to a .srec or MCAP (.mcap) file");
	tools::SourceOptions record_opts;
	record_opts.realtime = true;
	std::string record_out;
	uint64_t record_frames = 0;
	double record_seconds = 0;
	bool record_sync = false, record_images = false;
	add_source_options(*record_cmd, record_opts);
	record_cmd->add_option("-o,--output", record_out, "recording to write (.srec, or .mcap: docs/mcap.md)")
		->required();
	record_cmd->add_flag("--images", record_images,
			     "MCAP: also the eyes as JPEG (foxglove.CompressedImage), so Foxglove shows the video");
	record_cmd->add_option("-n,--frames", record_frames, "stop after this many frames");
	record_cmd->add_option("-t,--seconds", record_seconds, "stop after this many seconds");
	record_cmd->add_flag("--sync", record_sync, "flush every frame to the disk before the next");

	tools::add_info_command(app);

	auto *eval_cmd = app.add_subcommand("eval", "score labelled points against ground-truth masks");
	std::string eval_results, eval_truth, eval_name = "run", eval_csv, eval_errors_csv;
	int eval_border = 0;
	double eval_coverage = 0.02;
	bool eval_json = false;
	eval_cmd->add_option("-r,--results", eval_results, "NDJSON written by stereod process")->required();
	eval_cmd->add_option("-t,--truth", eval_truth, "folder with masks (stereod process --truth-dir, or <seq>.png)");
	tools::TrajectoryEvalOptions trajectory;
	eval_cmd->add_option("--poses", trajectory.poses,
			     "score the trajectory: TUM or KITTI poses file, or a --truth-dir folder");
	eval_cmd->add_option("--delta", trajectory.delta, "RPE over this many frames")->capture_default_str();
	eval_cmd->add_option("--window", trajectory.window, "drift over windows of this many frames")
		->capture_default_str();
	eval_cmd->add_option("--write-tum", trajectory.write_estimate, "also write the estimated trajectory (TUM)");
	eval_cmd->add_option("--name", eval_name, "row name in the table");
	eval_cmd->add_option("--border", eval_border, "ignore points this close to a mover's outline, pixels");
	eval_cmd->add_option("--min-coverage", eval_coverage, "second row: frames whose movers cover at least this");
	eval_cmd->add_option("--per-frame", eval_csv, "write per-frame scores to this CSV");
	eval_cmd->add_flag("--json", eval_json, "print one JSON object instead of the table");
	eval_cmd->add_option("--errors", eval_errors_csv,
			     "write every wrongly labelled point (position, mover, distance to its outline, depth)");
	bool eval_per_mover = false, eval_groups_only = false, eval_count_detail = false;
	eval_cmd->add_flag("--per-mover", eval_per_mover, "also a table of labels per mover (mask id)");
	eval_cmd->add_flag("--groups", eval_groups_only,
			   "score the moving-target groups against the truth's movers instead of the labels");
	WalkingRule eval_walking;
	eval_cmd->add_option("--walk-frames", eval_walking.frames,
			     "with --groups and a pixels-only reference: a mover walks when its blob moved against the "
			     "masks this many frames before or after (0: every mover walks)")
		->capture_default_str();
	eval_cmd->add_option("--walk-px", eval_walking.min_move_px, "... by at least this many pixels")
		->capture_default_str();
	eval_cmd->add_flag("--count-detail", eval_count_detail,
			   "with --groups: a second table of how the count goes wrong in the separated frames (too "
			   "many / too few groups, movers split or missed, groups on no mover) and, where the truth's "
			   "mover ids hold across frames, a third per mover with the frames it was missed in");

	auto *render_cmd = app.add_subcommand("render", "draw results onto the input's frames");
	tools::SourceOptions render_opts;
	std::string render_results, render_truth, render_out, render_video, render_sheet;
	std::vector<uint64_t> render_sheet_frames;
	int render_every = 1;
	bool render_arrows = false;
	add_source_options(*render_cmd, render_opts);
	render_cmd->add_option("-r,--results", render_results, "NDJSON from stereod process");
	render_cmd->add_option("-t,--truth", render_truth, "tint the ground truth's movers (a --truth-dir folder)");
	render_cmd->add_option("-o,--out", render_out, "folder for annotated PNGs and plot.png");
	render_cmd->add_option("--every", render_every, "write every Nth frame");
	render_cmd->add_option("--video", render_video, "also write an annotated video (MJPG .avi)");
	render_cmd->add_option("--sheet", render_sheet, "write a contact sheet of --frames to this PNG");
	render_cmd->add_option("--frames", render_sheet_frames, "frame numbers for the contact sheet")->delimiter(',');
	render_cmd->add_flag("--arrows", render_arrows, "draw each point's motion from the previous frame");

	tools::add_devices_command(app);
	tools::add_export_command(app);
	tools::add_map_command(app);
	tools::add_fleet_command(app);
	tools::add_reference_command(app);
	tools::add_calibrate_command(app);

	try {
		app.parse(argc, argv);
	} catch (const CLI::RuntimeError &e) {
		return e.get_exit_code(); // a subcommand that ran in its callback, with its exit status
	} catch (const CLI::ParseError &e) {
		return app.exit(e);
	} catch (const std::exception &e) {
		std::cerr << "stereoctl: " << e.what() << "\n";
		return 2;
	}
	try {
		if (*watch_cmd) {
			catch_interrupts();
			return watch(socket_path, raw, max_frames, timeout_s);
		}
		if (*record_cmd)
			return record(record_opts, record_out, record_frames, record_seconds, record_sync,
				      record_images);
		if (*eval_cmd) {
			if (eval_truth.empty() && trajectory.poses.empty()) {
				std::cerr << "stereoctl eval: give --truth (labels), --poses (trajectory), or both\n";
				return 2;
			}
			int rc = 0;
			if (!eval_truth.empty() && eval_groups_only)
				return eval_groups(eval_results, eval_truth, eval_name, eval_json, eval_count_detail,
						   eval_walking);
			if (!eval_truth.empty())
				rc = eval(eval_results, eval_truth, eval_name, eval_border, eval_coverage, eval_csv,
					  eval_json, eval_per_mover, eval_errors_csv);
			if (rc == 0 && !trajectory.poses.empty()) {
				trajectory.results = eval_results;
				trajectory.name = eval_name;
				trajectory.json = eval_json;
				rc = tools::eval_trajectory(trajectory);
			}
			return rc;
		}
		if (*render_cmd)
			return render(render_opts, render_results, render_truth, render_out, render_video, render_sheet,
				      render_sheet_frames, render_every, render_arrows);
	} catch (const std::exception &e) {
		std::cerr << "stereoctl: " << e.what() << "\n";
		return 2;
	}
	return 0;
}
