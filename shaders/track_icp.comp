#version 450
/* ICP association, residuals and reduction, shared-memory reduction only
 * (any device). The body is shaders/track_icp.glsl.h. */
#extension GL_GOOGLE_include_directive : require
#include "track_icp.glsl.h"
