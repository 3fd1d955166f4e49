# CTest fixture of the tests that stream a session through the live path (ROS 1 and DDS nodes, the
# stream soak): a quick simulated session (30 s trials at 200 Hz) and a linear free-space model
# fitted on it, in OUT (about 2 s).
#   cmake -DRCM=<rcm> -DOUT=<dir> -P make_test_session.cmake
file(REMOVE_RECURSE ${OUT})
execute_process(COMMAND ${RCM} simulate --quick --seed 1 --out ${OUT}/session
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "rcm simulate failed (${rc}): ${err}")
endif()
execute_process(COMMAND ${RCM} dynamics fit --model linear --out ${OUT}/model.json ${OUT}/session/free_space.csv
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "rcm dynamics fit failed (${rc}): ${err}")
endif()
