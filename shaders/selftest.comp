#version 450
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer Data { uint v[]; } data;
void main() { data.v[gl_GlobalInvocationID.x] += 1u; }
