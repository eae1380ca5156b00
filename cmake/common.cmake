# Component: common — helpers every component shares (the strict YAML config reader; the
# header-only atomic file writes, command-line parsing and timing live beside it).
ism_add_core_library(${PROJECT_NAME}_common
  SOURCES ${ISM_COMMON_SOURCES}
  LINK yaml-cpp)
