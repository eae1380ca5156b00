# Component: evaluation — camera labels and maps scored against human labels (SemanticKITTI, the
# synthetic drives' truth): a layer above perception and mapping (it builds maps to score them);
# evaluate_semantics, evaluate_map, make_camera_labels.

# Camera labels at lidar points scored against SemanticKITTI's human labels.
ism_add_core_library(${PROJECT_NAME}_evaluation
  SOURCES ${ISM_EVALUATION_SOURCES}
  LINK ${PROJECT_NAME}_perception ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti
       ${PROJECT_NAME}_mapping)

ism_add_tool(evaluate_semantics
  SOURCES src/tools/evaluate_semantics.cpp
  LINK ${PROJECT_NAME}_evaluation)
# The same map metric on any drive with labelled scans (the synthetic drives: demo, e2e tests).
ism_add_tool(evaluate_map
  SOURCES src/tools/evaluate_map.cpp
  LINK ${PROJECT_NAME}_evaluation)
# Training labels for the camera: a SemanticKITTI sequence's human lidar labels seen by its cameras.
ism_add_tool(make_camera_labels
  SOURCES src/tools/make_camera_labels.cpp
  LINK ${PROJECT_NAME}_evaluation)
ism_add_gtest(test_make_camera_labels
  SOURCES test/cli/test_make_camera_labels.cpp
  LINK ${PROJECT_NAME}_evaluation
  TOOL make_camera_labels TOOL_MACRO MAKE_CAMERA_LABELS_PATH)
ism_add_gtest(test_evaluate_map
  SOURCES test/cli/test_evaluate_map.cpp
  LINK ${PROJECT_NAME}_evaluation ${PROJECT_NAME}_synthetic
  TOOL evaluate_map TOOL_MACRO EVALUATE_MAP_PATH)

# The default ENet labelling path scored on the real SemanticKITTI frames of ../shared.
ism_add_gtest(test_real_semantics
  SOURCES test/accuracy/test_real_semantics.cpp
  LINK ${PROJECT_NAME}_evaluation)
