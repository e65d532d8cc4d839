// stereoctl devices: what each capture driver can see on this machine.
#include <iostream>

#include <CLI/CLI.hpp>

#include "drivers/aravis/aravis_camera.hpp"
#include "drivers/v4l2/v4l2_device.hpp"
#include "tools/subcommands.hpp"

namespace stereod::tools {
namespace {

int list_everything(bool aravis_only, bool v4l2_only)
{
	size_t found = 0;
	if (!v4l2_only) {
		std::cout << "aravis (GigE Vision, USB3 Vision):\n";
		const auto cameras = drivers::aravis::list_devices();
		for (const auto &d : cameras) {
			std::cout << "  " << d.id << "\n    " << d.transport
				  << (d.address.empty() ? "" : " at " + d.address) << ", " << d.vendor << " " << d.model
				  << ", serial " << d.serial << "\n";
			if (!d.error.empty()) {
				std::cout << "    cannot open: " << d.error << "\n";
				continue;
			}
			std::cout << "    up to " << d.max_width << "x" << d.max_height;
			if (d.max_fps > 0)
				std::cout << ", " << d.min_fps << ".." << d.max_fps << " fps";
			std::cout << "\n    pixel formats:";
			for (const auto &f : d.pixel_formats)
				std::cout << " " << f;
			std::cout << "\n    config: [aravis] left = \"" << d.id << "\"\n";
		}
		if (cameras.empty())
			std::cout << "  none found\n";
		found += cameras.size();
	}
	if (!aravis_only) {
		std::cout << "v4l2 (UVC and other Video4Linux2 devices):\n";
		const auto devices = drivers::v4l2::list_devices();
		size_t capture = 0;
		for (const auto &d : devices) {
			if (!d.error.empty()) {
				std::cout << "  " << d.path << ": " << d.error << "\n";
				continue;
			}
			++capture;
			std::cout << "  " << d.path << "\n    " << d.card << " (" << d.driver << ", " << d.bus << ")\n";
			for (const auto &f : d.formats)
				std::cout << "    " << f << "\n";
		}
		if (devices.empty())
			std::cout << "  none found\n";
		found += capture;
	}
	if (!aravis_only && !v4l2_only)
		std::cout
			<< "dc1394 (FireWire Bumblebee2 / XB3): start with source.driver = \"dc1394\"; it names every "
			   "GUID it finds\n";
	return found > 0 ? 0 : 1;
}

} // namespace

void add_devices_command(CLI::App &app)
{
	auto *cmd = app.add_subcommand("devices", "list the cameras each driver finds and what they can do");
	auto aravis_only = std::make_shared<bool>(false);
	auto v4l2_only = std::make_shared<bool>(false);
	cmd->add_flag("--aravis", *aravis_only, "only GigE Vision / USB3 Vision cameras");
	cmd->add_flag("--v4l2", *v4l2_only, "only V4L2 devices");
	cmd->callback([=] { throw CLI::RuntimeError(list_everything(*aravis_only, *v4l2_only)); });
}

} // namespace stereod::tools
