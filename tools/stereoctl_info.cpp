// `stereoctl info`: what a recording holds, every record checked. A .srec is read frame by frame; an MCAP file
// (ours or anyone's, uncompressed chunks) message by message, with its summary and indexes checked against
// the file, and what a cut file still holds said.
#include <iostream>
#include <map>

#include <CLI/CLI.hpp>

#include "drivers/replay/mcap.hpp"
#include "drivers/replay/mcap_recording.hpp"
#include "drivers/replay/recording.hpp"
#include "tools/subcommands.hpp"

namespace stereod::tools {
namespace {

/// A recording's frames as both formats' reports name them: "640x480 bgr8 stereo +depth".
std::string geometry_text(const FrameGeometry &g)
{
	return std::to_string(g.width) + "x" + std::to_string(g.height) + " " + std::string(to_string(g.format)) +
	       (g.stereo ? " stereo" : " mono") + (g.depth ? " +depth" : "") + (g.truth ? " +truth" : "");
}

void print_header(const std::string &path, const drivers::RecordingHeader &h)
{
	std::cout << path << ": recorded from " << h.source << " (" << h.description << ")\n"
		  << "  " << geometry_text(h.geometry) << ", nominal " << h.geometry.nominal_fps << " fps\n";
}

int info_srec(const std::string &path)
{
	drivers::RecordingReader reader(path);
	print_header(path, reader.header());
	StereoFrame frame;
	frame.allocate(reader.header().geometry);
	int64_t first = 0, last = 0;
	uint64_t n = 0;
	while (reader.next(frame)) {
		if (n++ == 0)
			first = frame.device_ns;
		last = frame.device_ns;
	}
	std::cout << "  " << reader.report().describe() << "\n";
	if (n > 1)
		std::cout << "  span " << static_cast<double>(last - first) * 1e-9 << " s, "
			  << static_cast<double>(n - 1) / (static_cast<double>(last - first) * 1e-9) << " fps\n";
	return 0;
}

int info_mcap(const std::string &path)
{
	drivers::mcap::Reader reader(path);
	reader.read_definitions();
	std::cout << path << ": MCAP, profile '" << reader.profile() << "', written by '" << reader.library() << "'\n";
	for (const auto &[id, channel] : reader.channels()) {
		const auto header = channel.metadata.find("recording_header");
		if (header == channel.metadata.end())
			continue;
		try {
			const auto h = drivers::parse_recording_header(header->second);
			std::cout << "  recorded from " << h.source << " (" << h.description << "), "
				  << geometry_text(h.geometry) << "\n";
		} catch (const std::exception &e) {
			std::cout << "  channel " << channel.topic << ": bad recording header: " << e.what() << "\n";
		}
		break;
	}
	struct Count {
		uint64_t messages = 0, bytes = 0, first = 0, last = 0;
	};
	std::map<uint16_t, Count> counts;
	drivers::mcap::MessageView m;
	while (reader.next(m)) {
		Count &c = counts[m.channel->id];
		if (c.messages++ == 0)
			c.first = m.log_time;
		c.last = m.log_time;
		c.bytes += m.data.size();
	}
	for (const auto &[id, channel] : reader.channels()) {
		const Count c = counts.count(id) ? counts.at(id) : Count{};
		std::string schema = "no schema";
		if (const auto s = reader.schemas().find(channel.schema_id); s != reader.schemas().end())
			schema = s->second.name + " (" + s->second.encoding + ")";
		std::cout << "  " << channel.topic << ": " << c.messages << " messages, " << c.bytes << " bytes, "
			  << channel.message_encoding << ", " << schema;
		if (c.messages > 1 && c.last > c.first)
			std::cout << ", "
				  << static_cast<double>(c.messages - 1) /
					     (static_cast<double>(c.last - c.first) * 1e-9)
				  << " per s";
		std::cout << "\n";
	}
	std::cout << "  " << reader.report().describe() << "\n";
	const auto index = reader.check_index();
	if (index.present)
		std::cout << "  summary: " << index.chunk_indexes << " chunk indexes, " << index.indexed_messages
			  << " messages indexed, statistics " << index.statistics_messages << ": "
			  << (index.valid ? "valid" : "INVALID") << "\n";
	else
		std::cout << "  summary: none" << (reader.report().clean_end ? "" : " (the writer did not finish)")
			  << "\n";
	for (const auto &problem : index.problems)
		if (index.present)
			std::cout << "    " << problem << "\n";
	return index.present && !index.valid ? 1 : 0;
}

} // namespace

void add_info_command(CLI::App &app)
{
	auto *cmd = app.add_subcommand("info", "describe a recording (.srec or .mcap) and check every record");
	auto path = std::make_shared<std::string>();
	cmd->add_option("recording", *path, "a .srec or .mcap file")->required();
	cmd->callback([path] {
		throw CLI::RuntimeError(drivers::mcap::is_mcap_file(*path) ? info_mcap(*path) : info_srec(*path));
	});
}

} // namespace stereod::tools
