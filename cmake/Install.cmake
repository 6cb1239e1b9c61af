# `cmake --install`: headers, the layer libraries, a CMake package (find_package(FibreMSS) gives
# fibremss::tasks, fibremss::core, fibremss::fibres, fibremss::io, fibremss::scene, fibremss::baselines), a
# pkg-config file for the core (pkg-config fibremss) and the fibremss tool. Everything is
# relocatable: `cmake --install build --prefix DIR` works for any DIR.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(FIBREMSS_INSTALLED_LAYERS tasks core fibres)
set(FIBREMSS_INSTALLED_HEADERS plugin/tasks plugin/core plugin/fibres)
if(NOT FIBREMSS_CORE_ONLY)
  list(APPEND FIBREMSS_INSTALLED_LAYERS io scene baselines)
  list(APPEND FIBREMSS_INSTALLED_HEADERS adapters/io adapters/scene adapters/baselines)
endif()
foreach(dir ${FIBREMSS_INSTALLED_HEADERS})
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${dir}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endforeach()
list(TRANSFORM FIBREMSS_INSTALLED_LAYERS PREPEND fibremss_)
install(TARGETS ${FIBREMSS_INSTALLED_LAYERS} EXPORT FibreMSSTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
if(TARGET fibremss_cli)
  file(RELATIVE_PATH FIBREMSS_BIN_TO_LIB ${CMAKE_INSTALL_FULL_BINDIR} ${CMAKE_INSTALL_FULL_LIBDIR})
  set_target_properties(fibremss_cli PROPERTIES INSTALL_RPATH "$ORIGIN/${FIBREMSS_BIN_TO_LIB}")
  install(TARGETS fibremss_cli RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()
install(EXPORT FibreMSSTargets NAMESPACE fibremss:: FILE FibreMSSTargets.cmake
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/FibreMSS)

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/FibreMSSConfig.cmake.in
  ${PROJECT_BINARY_DIR}/FibreMSSConfig.cmake
  INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/FibreMSS)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/FibreMSSConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/FibreMSSConfig.cmake ${PROJECT_BINARY_DIR}/FibreMSSConfigVersion.cmake
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/FibreMSS)

# The .pc file finds its prefix from its own place (${pcfiledir}), so it stays right wherever
# the tree is installed.
file(RELATIVE_PATH FIBREMSS_PC_TO_PREFIX ${CMAKE_INSTALL_FULL_LIBDIR}/pkgconfig
     ${CMAKE_INSTALL_PREFIX})
string(REGEX REPLACE "/$" "" FIBREMSS_PC_TO_PREFIX "${FIBREMSS_PC_TO_PREFIX}")
configure_file(${PROJECT_SOURCE_DIR}/cmake/fibremss.pc.in ${PROJECT_BINARY_DIR}/fibremss.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/fibremss.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)

# For a user of the installed tree: the README, the docs, the embedding examples' sources and the
# scene files and the shipped references (share/doc/FibreMSS, share/fibremss/scenes,
# share/fibremss/references).
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}/docs)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/scenes/example/ DESTINATION ${CMAKE_INSTALL_DOCDIR}/examples)
if(NOT FIBREMSS_CORE_ONLY)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/scenes/json/ DESTINATION ${CMAKE_INSTALL_DATADIR}/fibremss/scenes)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/scenes/references/
          DESTINATION ${CMAKE_INSTALL_DATADIR}/fibremss/references)
endif()
