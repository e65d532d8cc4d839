// The list of every driver this build has, kept apart from the registry itself so that a program may link
// one driver alone (the V4L2 check that runs inside the QEMU test bed does).
#include "drivers/builtin.hpp"

namespace stereod::drivers {

SourceRegistry SourceRegistry::with_builtin_drivers()
{
	SourceRegistry registry;
	register_sim(registry);
	register_replay(registry);
	register_datasets(registry);
	register_aravis(registry);
	register_v4l2(registry);
	register_dc1394(registry);
	return registry;
}

} // namespace stereod::drivers
