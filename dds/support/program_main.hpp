#pragma once
// The entry of rcm's DDS programs, one home for what each main() does:
// line-buffered output (log lines appear as they come when redirected to a
// file), SIGINT and SIGTERM ask the program to stop, and an error's exit
// status: 2 for bad input (a located InputError, or an std::invalid_argument
// such as fewer joint names than the model reads), 1 for anything else.

namespace rcm::dds_node {

// True once SIGINT or SIGTERM arrived; the programs' loops poll it.
bool is_stop_requested();

// Runs `run(argc, argv)` under the rules above; `name` prefixes the error.
int run_program(const char* name, int argc, char** argv, int (*run)(int, char**));

}  // namespace rcm::dds_node
