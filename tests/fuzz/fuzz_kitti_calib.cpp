// libFuzzer target: KITTI's calib_cam_to_cam.txt reader (a file from a dataset folder the user names).
#include <exception>

#include "drivers/replay/datasets.hpp"
#include "tests/fuzz/fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	try {
		(void)stereod::drivers::datasets::parse_kitti_calibration(stereod::fuzz::as_file(data, size, ".txt"));
	} catch (const std::exception &) {
	}
	return 0;
}
