// `stereoctl fleet`: every stereod on a DDS domain, one line per board (docs/ros2.md). Built on DDS discovery,
// not on our own protocol: the boards are found by the status topics their writers announce
// (rt/stereod/<name>/status, type stereod_msgs::msg::dds_::Status_), then each status topic is read.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>
#include <dds/dds.h>
#include <nlohmann/json.hpp>

#include "ros2_types.h"
#include "tools/subcommands.hpp"

namespace stereod::tools {
namespace {

struct Board {
	std::string topic;
	dds_entity_t reader = 0;
	bool seen = false;
	std::string source, state;
	double fps_capture = 0, fps_publish = 0, p50 = 0, p99 = 0, uptime = 0;
	uint64_t published = 0, drops = 0;
	uint32_t clients = 0, groups = 0;
	std::chrono::steady_clock::time_point last;
};

struct FleetOptions {
	int domain = 0;
	double seconds = 3;
	bool follow = false;
	bool json = false;
};

void print(const std::map<std::string, Board> &boards, bool json)
{
	const auto now = std::chrono::steady_clock::now();
	if (json) {
		for (const auto &[name, b] : boards)
			std::cout << nlohmann::json{{"name", name},
						    {"seen", b.seen},
						    {"source", b.source},
						    {"state", b.state},
						    {"fps", b.fps_publish},
						    {"frames", b.published},
						    {"drops", b.drops},
						    {"latency_p50_ms", b.p50},
						    {"latency_p99_ms", b.p99},
						    {"groups", b.groups},
						    {"clients", b.clients}}
					     .dump()
				  << "\n";
		return;
	}
	std::printf("%-16s %-8s %-13s %7s %9s %7s %9s %9s %6s %7s %6s\n", "BOARD", "SOURCE", "STATE", "FPS", "FRAMES",
		    "DROPS", "P50 ms", "P99 ms", "GROUPS", "CLIENTS", "AGE s");
	for (const auto &[name, b] : boards) {
		if (!b.seen) {
			std::printf("%-16s (found on the domain, no status yet)\n", name.c_str());
			continue;
		}
		const double age = std::chrono::duration<double>(now - b.last).count();
		std::printf("%-16s %-8s %-13s %7.1f %9llu %7llu %9.1f %9.1f %6u %7u %6.1f\n", name.c_str(),
			    b.source.c_str(), b.state.c_str(), b.fps_publish,
			    static_cast<unsigned long long>(b.published), static_cast<unsigned long long>(b.drops),
			    b.p50, b.p99, b.groups, b.clients, age);
	}
	if (boards.empty())
		std::printf("(no stereod found on this domain)\n");
	std::fflush(stdout);
}

int fleet(const FleetOptions &o)
{
	const dds_entity_t participant =
		dds_create_participant(static_cast<dds_domainid_t>(o.domain), nullptr, nullptr);
	if (participant < 0) {
		std::cerr << "stereoctl fleet: cannot join DDS domain " << o.domain << ": "
			  << dds_strretcode(participant) << "\n";
		return 1;
	}
	const dds_entity_t publications =
		dds_create_reader(participant, DDS_BUILTIN_TOPIC_DCPSPUBLICATION, nullptr, nullptr);
	// Best effort: such a reader matches every board's status writer, reliable (dds.qos = "reliable") or best
	// effort ("sensor_data"); a reliable one would miss the latter (integration.dds_two_boards found it).
	dds_qos_t *qos = dds_create_qos();
	dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
	dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
	std::map<std::string, Board> boards;
	constexpr int kMax = 16;
	void *samples[kMax] = {};
	dds_sample_info_t infos[kMax];
	const auto start = std::chrono::steady_clock::now();
	auto next_print = start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
					  std::chrono::duration<double>(o.seconds));
	for (;;) {
		int n = dds_take(publications, samples, infos, kMax, kMax);
		for (int i = 0; i < n; ++i) {
			if (!infos[i].valid_data)
				continue;
			const auto *e = static_cast<const dds_builtintopic_endpoint_t *>(samples[i]);
			const std::string topic = e->topic_name;
			const std::string prefix = "rt/stereod/", suffix = "/status";
			if (topic.rfind(prefix, 0) != 0 || topic.size() <= prefix.size() + suffix.size() ||
			    topic.compare(topic.size() - suffix.size(), suffix.size(), suffix) != 0 ||
			    std::string(e->type_name) != stereod_msgs_msg_dds__Status__desc.m_typename)
				continue;
			const std::string name =
				topic.substr(prefix.size(), topic.size() - prefix.size() - suffix.size());
			if (boards.count(name))
				continue;
			Board b;
			b.topic = topic;
			const dds_entity_t t = dds_create_topic(participant, &stereod_msgs_msg_dds__Status__desc,
								topic.c_str(), nullptr, nullptr);
			b.reader = t < 0 ? t : dds_create_reader(participant, t, qos, nullptr);
			boards.emplace(name, b);
		}
		if (n > 0)
			dds_return_loan(publications, samples, n);
		for (auto &[name, b] : boards) {
			if (b.reader < 0)
				continue;
			n = dds_take(b.reader, samples, infos, kMax, kMax);
			for (int i = 0; i < n; ++i) {
				if (!infos[i].valid_data)
					continue;
				const auto *m = static_cast<const stereod_msgs_msg_dds__Status_ *>(samples[i]);
				b.seen = true;
				b.source = m->source;
				b.state = m->source_state;
				b.fps_capture = m->fps_capture;
				b.fps_publish = m->fps_publish;
				b.published = m->frames_published;
				b.drops = m->drops;
				b.p50 = m->latency_p50_ms;
				b.p99 = m->latency_p99_ms;
				b.clients = m->clients;
				b.groups = m->groups_in_view;
				b.uptime = m->uptime_s;
				b.last = std::chrono::steady_clock::now();
			}
			if (n > 0)
				dds_return_loan(b.reader, samples, n);
		}
		const auto now = std::chrono::steady_clock::now();
		if (now >= next_print) {
			print(boards, o.json);
			if (!o.follow)
				break;
			next_print = now + std::chrono::seconds(1);
		}
		std::this_thread::sleep_for(std::chrono::milliseconds(20));
	}
	dds_delete_qos(qos);
	dds_delete(participant);
	return boards.empty() ? 1 : 0;
}

} // namespace

void add_fleet_command(CLI::App &app)
{
	auto *cmd = app.add_subcommand("fleet", "every stereod on a DDS domain, one line per board (docs/ros2.md)");
	auto o = std::make_shared<FleetOptions>();
	cmd->add_option("-d,--domain", o->domain, "DDS domain id (the boards' dds.domain)")->check(CLI::Range(0, 232));
	cmd->add_option("-t,--seconds", o->seconds, "listen this long before printing (status comes every second)");
	cmd->add_flag("-f,--follow", o->follow, "keep printing every second until interrupted");
	cmd->add_flag("--json", o->json, "one JSON object per board");
	cmd->callback([o] { throw CLI::RuntimeError(fleet(*o)); });
}

} // namespace stereod::tools
