# `cmake --install`: headers, the layer libraries, a CMake package (find_package(FibreMSS) gives
# fibremss::core, fibremss::fibres, fibremss::io, fibremss::scene, fibremss::baselines) and a
# pkg-config file for the core (pkg-config fibremss).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

foreach(dir plugin/core plugin/fibres adapters/io adapters/scene adapters/baselines scenes)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${dir}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endforeach()
install(TARGETS fibremss_core fibremss_fibres fibremss_io fibremss_scene fibremss_baselines
  EXPORT FibreMSSTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(TARGETS fibremss_cli RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(EXPORT FibreMSSTargets NAMESPACE fibremss:: FILE FibreMSSTargets.cmake
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/FibreMSS)

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/FibreMSSConfig.cmake.in
  ${PROJECT_BINARY_DIR}/FibreMSSConfig.cmake
  INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/FibreMSS)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/FibreMSSConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/FibreMSSConfig.cmake ${PROJECT_BINARY_DIR}/FibreMSSConfigVersion.cmake
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/FibreMSS)

configure_file(${PROJECT_SOURCE_DIR}/cmake/fibremss.pc.in ${PROJECT_BINARY_DIR}/fibremss.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/fibremss.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
