#version 450
/* ICP association, residuals and reduction with subgroup additions (devices
 * with subgroup arithmetic). The body is shaders/track_icp.glsl.h. */
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#define TRACK_ICP_SUBGROUP 1
#include "track_icp.glsl.h"
