// The Cityscapes label set: the one class id space of this package. Segmentation publishes
// Cityscapes labelIds (0..33) in mono8 images, the synthetic generator writes labelIds in its
// label images and (lower 16 bits of) its .label files, and the semantic map stores labelIds.
// trainIds (0..18, 255 = ignore) are what Cityscapes networks predict and what mIoU is
// reported over. Values from the official cityscapesScripts labels.py.
#pragma once

#include <array>
#include <cstdint>

namespace inekf_semantic_mapping {
namespace cityscapes {

struct LabelInfo {
  std::uint8_t label_id;
  const char* name;
  std::uint8_t train_id;  // 255: ignored in evaluation
  std::uint8_t r, g, b;
};

constexpr std::uint8_t kIgnoreTrainId = 255;
constexpr int kNumLabelIds = 34;
constexpr int kNumTrainIds = 19;

constexpr std::array<LabelInfo, kNumLabelIds> kLabels = {{
    {0, "unlabeled", 255, 0, 0, 0},
    {1, "ego vehicle", 255, 0, 0, 0},
    {2, "rectification border", 255, 0, 0, 0},
    {3, "out of roi", 255, 0, 0, 0},
    {4, "static", 255, 0, 0, 0},
    {5, "dynamic", 255, 111, 74, 0},
    {6, "ground", 255, 81, 0, 81},
    {7, "road", 0, 128, 64, 128},
    {8, "sidewalk", 1, 244, 35, 232},
    {9, "parking", 255, 250, 170, 160},
    {10, "rail track", 255, 230, 150, 140},
    {11, "building", 2, 70, 70, 70},
    {12, "wall", 3, 102, 102, 156},
    {13, "fence", 4, 190, 153, 153},
    {14, "guard rail", 255, 180, 165, 180},
    {15, "bridge", 255, 150, 100, 100},
    {16, "tunnel", 255, 150, 120, 90},
    {17, "pole", 5, 153, 153, 153},
    {18, "polegroup", 255, 153, 153, 153},
    {19, "traffic light", 6, 250, 170, 30},
    {20, "traffic sign", 7, 220, 220, 0},
    {21, "vegetation", 8, 107, 142, 35},
    {22, "terrain", 9, 152, 251, 152},
    {23, "sky", 10, 70, 130, 180},
    {24, "person", 11, 220, 20, 60},
    {25, "rider", 12, 255, 0, 0},
    {26, "car", 13, 0, 0, 142},
    {27, "truck", 14, 0, 0, 70},
    {28, "bus", 15, 0, 60, 100},
    {29, "caravan", 255, 0, 0, 90},
    {30, "trailer", 255, 0, 0, 110},
    {31, "train", 16, 0, 80, 100},
    {32, "motorcycle", 17, 0, 0, 230},
    {33, "bicycle", 18, 119, 11, 32},
}};

// Commonly used labelIds, by name.
enum LabelId : std::uint8_t {
  kUnlabeled = 0,
  kGround = 6,
  kRoad = 7,
  kSidewalk = 8,
  kParking = 9,
  kBuilding = 11,
  kWall = 12,
  kFence = 13,
  kPole = 17,
  kTrafficLight = 19,
  kTrafficSign = 20,
  kVegetation = 21,
  kTerrain = 22,
  kSky = 23,
  kPerson = 24,
  kRider = 25,
  kCar = 26,
  kTruck = 27,
  kBus = 28,
  kBicycle = 33,
};

// labelId -> trainId (255 for ignored and out-of-range ids).
constexpr std::uint8_t labelIdToTrainId(int label_id) {
  return (label_id >= 0 && label_id < kNumLabelIds) ? kLabels[label_id].train_id : kIgnoreTrainId;
}

// trainId -> labelId (0 "unlabeled" for out-of-range ids).
constexpr std::uint8_t trainIdToLabelId(int train_id) {
  for (const LabelInfo& info : kLabels) {
    if (info.train_id == train_id && train_id != kIgnoreTrainId) return info.label_id;
  }
  return kUnlabeled;
}

constexpr const char* labelName(int label_id) {
  return (label_id >= 0 && label_id < kNumLabelIds) ? kLabels[label_id].name : "invalid";
}

}  // namespace cityscapes
}  // namespace inekf_semantic_mapping
