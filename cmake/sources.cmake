# Each library's sources, once: the catkin build (cmake/<component>.cmake), and the sanitizer and
# fuzz build (test/fuzz/CMakeLists.txt, clang-14) read these lists, so they cannot drift apart.
# Paths are relative to the repository root.

# common: the strict YAML config reader.
set(ISM_COMMON_SOURCES src/common/yaml_reader.cpp)
# kitti: KITTI raw I/O (Eigen only).
set(ISM_KITTI_SOURCES
  src/kitti/calibration.cpp
  src/kitti/drive_timeline.cpp
  src/kitti/gps_degradation.cpp
  src/kitti/mercator.cpp
  src/kitti/oxts.cpp
  src/kitti/poses.cpp
  src/kitti/raw_drive.cpp
  src/kitti/sensor_stream.cpp
  src/kitti/timestamps.cpp
  src/kitti/velodyne.cpp)
# lie, estimation: Lie groups; the filters, the Localizer, the smoother and the pose graph.
set(ISM_LIE_SOURCES src/lie/so3.cpp src/lie/se23.cpp)
set(ISM_ESTIMATION_SOURCES
  src/estimation/error_dynamics.cpp src/estimation/imu_filters.cpp
  src/estimation/localizer.cpp src/estimation/localizer_config.cpp
  src/estimation/standstill_detector.cpp
  src/estimation/lazy_start.cpp
  src/estimation/smoother.cpp src/estimation/pose_graph.cpp
  src/estimation/selected_inverse.cpp)
# localization_session: the streaming session of inekf_node and inekf_offline.
set(ISM_LOCALIZATION_SESSION_SOURCES src/estimation/localization_session.cpp)
# estimation_oxts: the session over KITTI OXTS, the loop closure, the smoothed posterior graph.
set(ISM_ESTIMATION_OXTS_SOURCES
  src/estimation/oxts_run.cpp src/estimation/loop_closure.cpp
  src/estimation/smoothed_posterior_graph.cpp)
# registration: PCL GICP for the loop closure.
set(ISM_REGISTRATION_SOURCES src/registration/icp_registration.cpp)
# projection: lidar-to-camera projection and the label geometry check (Eigen only).
set(ISM_PROJECTION_SOURCES src/perception/projection.cpp src/perception/label_geometry.cpp
  src/perception/curb_detection.cpp)
# perception: model cards (YAML only) and the Segmenter (OpenCV dnn).
set(ISM_MODEL_CARD_SOURCES src/perception/model_card.cpp)
set(ISM_PERCEPTION_SOURCES ${ISM_MODEL_CARD_SOURCES} src/perception/segmenter.cpp
  src/perception/segmenter_input.cpp src/perception/dnn_bilinear_resize.cpp src/perception/segmenter_labels.cpp)
# mapping: SemanticOcTree, the hashed grid, map files, the offline mapping and the session, grids.
set(ISM_MAPPING_SOURCES
  src/mapping/semantic_classes.cpp
  src/mapping/semantic_octree.cpp
  src/mapping/semantic_octree_insertion.cpp
  src/mapping/semantic_octree_io.cpp
  src/mapping/hashed_voxel_grid.cpp
  src/mapping/map_io.cpp
  src/mapping/offline_mapping.cpp
  src/mapping/map_label_images.cpp
  src/mapping/semantic_mapping_config.cpp
  src/mapping/scan_label_pairing.cpp
  src/mapping/semantic_mapping_session.cpp
  src/mapping/grid_projection.cpp)
# evaluation: scores of camera labels and maps against human labels (above perception and mapping).
set(ISM_EVALUATION_SOURCES src/evaluation/semantic_evaluation.cpp)
# synthetic: the KITTI-format drive generator.
set(ISM_SYNTHETIC_SOURCES
  src/synthetic/world.cpp
  src/synthetic/world_town.cpp
  src/synthetic/world_io.cpp
  src/synthetic/route.cpp
  src/synthetic/sensors.cpp
  src/synthetic/drive_generator.cpp
  src/synthetic/label_iou.cpp)
# The ROS-facing message conversions of the nodes.
set(ISM_KITTI_ROS_SOURCES src/ros/kitti_conversions.cpp src/ros/drive_publishers.cpp)
set(ISM_LOCALIZATION_ROS_SOURCES
  src/ros/localization_conversions.cpp src/ros/kitti_bag_conventions.cpp
  src/ros/odometry_output.cpp src/ros/levelled_velocity_pairing.cpp
  src/ros/localization_diagnostics.cpp)
set(ISM_MAPPING_ROS_SOURCES
  src/ros/mapping_conversions.cpp src/ros/map_display.cpp src/ros/map_services.cpp
  src/ros/label_camera.cpp src/ros/mapping_diagnostics.cpp src/ros/semantic_octomap_node_core.cpp
  src/ros/shutdown_log.cpp)
set(ISM_SEGMENTATION_ROS_SOURCES src/ros/segmentation_node_core.cpp)
# The segmentation and map nodes as nodelets (nodelet_plugins.xml).
set(ISM_NODELET_SOURCES src/nodelets/pipeline_nodelets.cpp)
