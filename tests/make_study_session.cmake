# CTest fixture of tests/test_study.cpp: its small simulated bench (the
# configuration in tests/data/study_bench_config.json), written once per ctest
# run instead of once per test process.
#   cmake -DRCM=<rcm> -DCONFIG=<json> -DOUT=<dir> -P make_study_session.cmake
file(REMOVE_RECURSE ${OUT})
execute_process(COMMAND ${RCM} simulate --config ${CONFIG} --seed 1 --out ${OUT}
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "rcm simulate failed (${rc}): ${err}")
endif()
