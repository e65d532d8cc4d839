// libFuzzer target: the .srec reader (docs/recording-format.md). A cut, flipped or forged recording must be
// refused with a message, or read up to its first bad record with a report, never crash or allocate without
// bound.
#include <stdexcept>

#include "drivers/replay/recording.hpp"
#include "tests/fuzz/fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	using namespace stereod;
	try {
		drivers::RecordingReader reader(fuzz::as_file(data, size, ".srec"));
		StereoFrame frame;
		frame.allocate(reader.header().geometry);
		for (int frames = 0; frames < 1000 && reader.next(frame); ++frames) {
		}
		(void)reader.report().describe();
	} catch (const std::runtime_error &) {
	}
	return 0;
}
