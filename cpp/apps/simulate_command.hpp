#pragma once
// `pnet simulate SCENE [options]`: runs a scene and writes its frames.
namespace pnet::apps {

/// argv[0] is "simulate". Returns the process exit code: 0 done, 1 the
/// simulation failed (blow-up; the frames written so far stay valid), 2 bad
/// input (usage, scene file, model file).
int simulate_command(int argc, char** argv);

}  // namespace pnet::apps
