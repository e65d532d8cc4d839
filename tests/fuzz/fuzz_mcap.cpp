// libFuzzer target: the MCAP reader (drivers/replay/mcap.hpp) and stereod's frames in it. A cut, flipped or
// forged MCAP file must be refused with a message, or read up to its first bad record with a report, and its
// summary checked without trusting any offset in it: never a crash or an allocation without bound.
#include <stdexcept>

#include "drivers/replay/mcap.hpp"
#include "drivers/replay/mcap_recording.hpp"
#include "tests/fuzz/fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	using namespace stereod;
	const std::string path = fuzz::as_file(data, size, ".mcap");
	try {
		drivers::mcap::Reader reader(path);
		drivers::mcap::MessageView m;
		for (int messages = 0; messages < 10000 && reader.next(m); ++messages) {
		}
		(void)reader.report().describe();
		(void)reader.check_index();
	} catch (const std::runtime_error &) {
	}
	try {
		auto frames = drivers::open_recording(path);
		StereoFrame frame;
		frame.allocate(frames->recording_header().geometry);
		for (int n = 0; n < 100 && frames->next_frame(frame); ++n) {
		}
		(void)frames->describe_end();
	} catch (const std::exception &) {
	}
	return 0;
}
