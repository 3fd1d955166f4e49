# The install's find_package(rcm) test: configure examples/ as an outside user
# does, with nothing of rcm but the temporary prefix, build one example, check
# that rcm came from that prefix, then run the example under its check.
#   cmake -DSOURCE=<examples dir> -DPREFIX=<install prefix> -DBINARY=<scratch dir>
#         -DCXX=<compiler> [-DLAUNCHER=ccache] [-DGENERATOR=...] -DBUILD_TYPE=<type>
#         [-DCXX_FLAGS=... -DLINK_FLAGS=...] -DEXAMPLE=<name>
#         -DRUN=<check command, ending in -->  -DARGS=<the example's arguments>
#         -P build_installed_example.cmake
file(REMOVE_RECURSE ${BINARY})
string(TOUPPER "${BUILD_TYPE}" BUILD_TYPE_UPPER)
# The library's build type and flags (an instrumented library needs an
# instrumented program), given as the type's own flags.
set(configure ${CMAKE_COMMAND} -S ${SOURCE} -B ${BINARY} -DCMAKE_BUILD_TYPE=${BUILD_TYPE}
    -DCMAKE_PREFIX_PATH=${PREFIX} -DCMAKE_CXX_COMPILER=${CXX}
    "-DCMAKE_CXX_FLAGS_${BUILD_TYPE_UPPER}=${CXX_FLAGS}" "-DCMAKE_EXE_LINKER_FLAGS_${BUILD_TYPE_UPPER}=${LINK_FLAGS}"
    # Only the prefix: neither the package registry nor an earlier install elsewhere.
    -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF -DCMAKE_FIND_USE_SYSTEM_PACKAGE_REGISTRY=OFF)
if(GENERATOR)
  list(APPEND configure -G ${GENERATOR})
endif()
if(LAUNCHER)
  list(APPEND configure -DCMAKE_CXX_COMPILER_LAUNCHER=${LAUNCHER})
endif()
execute_process(COMMAND ${configure} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "configuring ${SOURCE} against ${PREFIX} failed (${rc}):\n${out}\n${err}")
endif()

# find_package(rcm) must have read the installed config, nothing else.
file(STRINGS ${BINARY}/CMakeCache.txt rcm_dir REGEX "^rcm_DIR:")
string(REGEX REPLACE "^rcm_DIR:[A-Z]+=" "" rcm_dir "${rcm_dir}")
file(REAL_PATH "${rcm_dir}" rcm_dir)
file(REAL_PATH "${PREFIX}" prefix)
string(FIND "${rcm_dir}" "${prefix}/" at)
if(NOT at EQUAL 0)
  message(FATAL_ERROR "find_package(rcm) found ${rcm_dir}, not the config installed under ${prefix}")
endif()
message(STATUS "find_package(rcm): ${rcm_dir}")

execute_process(COMMAND ${CMAKE_COMMAND} --build ${BINARY} --target ${EXAMPLE}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "building ${EXAMPLE} against the installed rcm failed (${rc}):\n${out}\n${err}")
endif()
# Its compile lines include the installed headers, never the source tree's.
file(GLOB_RECURSE flags_files ${BINARY}/CMakeFiles/${EXAMPLE}.dir/flags.make)
if(flags_files)
  file(READ ${flags_files} flags)
  get_filename_component(source_root ${SOURCE} DIRECTORY)
  if(flags MATCHES "${source_root}/include")
    message(FATAL_ERROR "${EXAMPLE} was compiled with ${source_root}/include on its include path:\n${flags}")
  endif()
endif()

execute_process(COMMAND ${RUN} ${BINARY}/${EXAMPLE} ${ARGS} RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${EXAMPLE} built against the installed rcm failed its check (${rc})")
endif()
