# Debian's libceres-dev pulls in ATLAS, and its CMake config exports ATLAS's
# libf77blas and libatlas (hard-coded, and again through FindBLAS, which prefers
# ATLAS). Linked ahead of libblas.so.3 (the OpenBLAS alternative), ATLAS's
# single-threaded sgemm_ then won the symbol lookup for LibTorch too: training
# ran 2.6x slower than with OpenBLAS, and --threads 2 was no faster than 1
# (README.md, "Dependencies"). The generic libblas/liblapack provide every BLAS
# and LAPACK symbol Ceres and SuiteSparse call. Set BLA_VENDOR to Generic before
# finding Ceres, and call this after.
function(rcm_remove_atlas_from_ceres)
  foreach(target Ceres::ceres SuiteSparse::Config BLAS::BLAS LAPACK::LAPACK)
    if(TARGET ${target})
      get_target_property(links ${target} INTERFACE_LINK_LIBRARIES)
      if(links)
        list(FILTER links EXCLUDE REGEX "/lib(f77blas|atlas)\\.so$")
        set_target_properties(${target} PROPERTIES INTERFACE_LINK_LIBRARIES "${links}")
      endif()
    endif()
  endforeach()
endfunction()
