// The GL sensor's per-pixel state and random numbers (see vhgen/render/sensor_gl.py).
// Every array is the image in raster order (row 0 first), one entry per pixel.

layout(std430, binding = 0) buffer Val { float val[]; };      // depth (m) or disparity (px), 0 where invalid
layout(std430, binding = 1) buffer Flags { uint flags[]; };   // bit 0 valid, bit 1 + k hole cause k
layout(std430, binding = 2) buffer Ids { uint ids[]; };       // packed ids, moved with the pixels
layout(std430, binding = 3) buffer Inc { float inc[]; };      // |cos| incidence, moved with the pixels

uniform ivec2 size;      // (W, H)
uniform float fb;        // f b, px m: d = fb / z
uniform uvec2 key;       // the frame's random key (two words drawn from its Generator)

const uint VALID = 1u;

uint cause_bit(uint k) { return 2u << k; }

// PCG's output permutation as an integer hash (Jarzynski & Olano, "Hash Functions for
// GPU Rendering", JCGT 2020): counter-based, so a pixel's draws depend only on
// (key, stream, pixel, draw), never on the order in which invocations run. stream: the
// effect's position in the sensor (each effect its own numbers).
uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

uint draw_u32(uint stream, uint pixel, uint draw) {
    return pcg_hash(key.x ^ pcg_hash(key.y + pcg_hash(stream * 8u + draw + pcg_hash(pixel))));
}

// uniform in (0, 1) with 24 bits
float draw_uniform(uint stream, uint pixel, uint draw) {
    return (float(draw_u32(stream, pixel, draw) >> 8u) + 0.5) * (1.0 / 16777216.0);
}

// N(0, 1) by Box-Muller from draws (draw, draw + 1)
float draw_normal(uint stream, uint pixel, uint draw) {
    float u1 = draw_uniform(stream, pixel, draw);
    float u2 = draw_uniform(stream, pixel, draw + 1u);
    return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}

bool is_valid(uint p) { return (flags[p] & VALID) != 0u; }

// a valid pixel becomes a hole of cause k, 0 in val
void remove_pixel(uint p, uint k) {
    if ((flags[p] & VALID) != 0u) {
        flags[p] = (flags[p] & ~VALID) | cause_bit(k);
        val[p] = 0.0;
    }
}
