#include "client/view/materials.h"

namespace terrane::view {
namespace {

// The article's 23 default materials (common/voxel/voxel.h order).
constexpr std::array<MaterialStyle, 23> kStyles = {{
    {0, 0, 0, 0.0f},         // Air (never meshed)
    {52, 104, 150, 0.0f},    // Water
    {92, 140, 58, 0.1f},     // Grass
    {88, 92, 98, 0.8f},      // Slate
    {150, 150, 146, 0.9f},   // Concrete
    {150, 72, 56, 0.9f},     // Brick
    {214, 196, 140, 0.0f},   // Sand
    {146, 104, 62, 0.8f},    // WoodPlanks
    {118, 112, 106, 0.85f},  // Rock
    {170, 206, 224, 0.5f},   // Glacier
    {238, 242, 246, 0.0f},   // Snow
    {196, 150, 104, 0.7f},   // Sandstone
    {100, 78, 58, 0.05f},    // Mud
    {62, 62, 66, 0.9f},      // Basalt
    {120, 92, 64, 0.2f},     // Ground
    {168, 60, 30, 0.7f},     // CrackedLava
    {54, 54, 58, 0.6f},      // Asphalt
    {124, 120, 112, 0.8f},   // Cobblestone
    {180, 214, 236, 0.5f},   // Ice
    {74, 124, 46, 0.1f},     // LeafyGrass
    {226, 222, 214, 0.3f},   // Salt
    {190, 184, 160, 0.75f},  // Limestone
    {140, 136, 130, 0.8f},   // Pavement
}};
constexpr MaterialStyle kUnknown{160, 160, 160, 0.5f};

}  // namespace

const MaterialStyle& material_style(Material m) { return m < kStyles.size() ? kStyles[m] : kUnknown; }

}  // namespace terrane::view
