# CTest fixture of the install tests: `cmake --install` of the build into a
# temporary prefix, and again with DESTDIR and the configured prefix, as a
# packager does.
#   cmake -DBUILD=<build dir> -DPREFIX=<dir> -DDESTDIR_ROOT=<dir> -P install_to_prefix.cmake
file(REMOVE_RECURSE ${PREFIX} ${DESTDIR_ROOT})
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD} --prefix ${PREFIX}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cmake --install ${BUILD} --prefix ${PREFIX} failed (${rc}):\n${out}\n${err}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -E env DESTDIR=${DESTDIR_ROOT} ${CMAKE_COMMAND} --install ${BUILD}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "DESTDIR=${DESTDIR_ROOT} cmake --install ${BUILD} failed (${rc}):\n${out}\n${err}")
endif()
message(STATUS "installed into ${PREFIX} and under ${DESTDIR_ROOT}")
