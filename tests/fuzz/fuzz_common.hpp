#pragma once
// Shared by the libFuzzer targets: the readers under test take paths, as the daemon gives them files, so each
// input is written to a file of its own (one per process, reused) and read back through the real code path.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include <unistd.h>

namespace stereod::fuzz {

/// `data` as the content of a scratch file; returns its path.
inline const std::string &as_file(const uint8_t *data, size_t size, const char *suffix)
{
	static const std::string path = "/tmp/stereod-fuzz-" + std::to_string(::getpid()) + suffix;
	std::FILE *f = std::fopen(path.c_str(), "wb");
	if (f == nullptr)
		__builtin_trap(); // the fuzzer's own environment is broken, not the code under test
	if (size > 0)
		std::fwrite(data, 1, size, f);
	std::fclose(f);
	return path;
}

} // namespace stereod::fuzz
