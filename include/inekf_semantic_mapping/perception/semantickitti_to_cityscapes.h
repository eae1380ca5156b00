// SemanticKITTI's human point labels (the lower 16 bits of a .label entry) mapped to the Cityscapes
// labelIds this package predicts, so camera labels can be scored against the human labels of real
// lidar scans. ROS-free, header-only.
//
// Choices where the two label sets do not line up:
//  - parking and lane-marking -> road: Cityscapes' "parking" is not a trained class, and a
//    Cityscapes network labels both as road (lane markings are part of the road there).
//  - trunk -> vegetation: Cityscapes annotates trees, trunks included, as vegetation.
//  - bicyclist / motorcyclist -> rider: the person on the bike (Cityscapes labels the bike apart).
//  - on-rails -> train: Cityscapes' "train" class covers trams and trains.
//  - other-vehicle -> ignored: it mixes trailers, caravans, vans on trailers..., which Cityscapes
//    labels as caravan / trailer (not trained) or truck; no one right answer to score against.
//  - unlabeled, outlier, other-ground, other-structure, other-object -> ignored: no Cityscapes
//    trained class matches them.
#pragma once

#include <array>
#include <cstdint>

#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace perception {

// The labelId value meaning "not scored" (no Cityscapes labelId is this large).
constexpr std::uint8_t kIgnoredLabel = 255;

// SemanticKITTI class (0..259) -> Cityscapes labelId, kIgnoredLabel where not scored.
constexpr std::uint8_t semanticKittiToCityscapes(std::uint16_t semantic_kitti_class) {
  namespace cs = cityscapes;
  switch (semantic_kitti_class) {
    case 10:   // car
    case 252:  // moving-car
      return cs::kCar;
    case 11:  // bicycle
      return cs::kBicycle;
    case 13:   // bus
    case 257:  // moving-bus
      return cs::kBus;
    case 15:  // motorcycle
      return 32;
    case 16:      // on-rails
    case 256:     // moving-on-rails
      return 31;  // train
    case 18:      // truck
    case 258:     // moving-truck
      return cs::kTruck;
    case 30:   // person
    case 254:  // moving-person
      return cs::kPerson;
    case 31:   // bicyclist
    case 32:   // motorcyclist
    case 253:  // moving-bicyclist
    case 255:  // moving-motorcyclist
      return cs::kRider;
    case 40:  // road
    case 44:  // parking
    case 60:  // lane-marking
      return cs::kRoad;
    case 48:  // sidewalk
      return cs::kSidewalk;
    case 50:  // building
      return cs::kBuilding;
    case 51:  // fence
      return cs::kFence;
    case 70:  // vegetation
    case 71:  // trunk
      return cs::kVegetation;
    case 72:  // terrain
      return cs::kTerrain;
    case 80:  // pole
      return cs::kPole;
    case 81:  // traffic-sign
      return cs::kTrafficSign;
    default:  // unlabeled, outlier, other-vehicle, other-ground, other-structure, other-object
      return kIgnoredLabel;
  }
}

// The Cityscapes labelIds a mapped SemanticKITTI label can take: the classes that are scored.
constexpr std::array<std::uint8_t, 16> kScoredCityscapesLabels = {
    cityscapes::kRoad,   cityscapes::kSidewalk,    cityscapes::kBuilding,   cityscapes::kFence,
    cityscapes::kPole,   cityscapes::kTrafficSign, cityscapes::kVegetation, cityscapes::kTerrain,
    cityscapes::kPerson, cityscapes::kRider,       cityscapes::kCar,        cityscapes::kTruck,
    cityscapes::kBus,    31 /* train */,           32 /* motorcycle */,     cityscapes::kBicycle};

}  // namespace perception
}  // namespace inekf_semantic_mapping
