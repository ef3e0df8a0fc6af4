"""GLSL 3.30 sources. Lighting happens in linear light in view space (the lights move with the
camera, so an orbited face stays readable) and is gamma-encoded at the end of each surface shader,
so the optional post pass (FXAA, supersample resolve) works on perceptual values as FXAA expects.
Variants are separate programs chosen by #define: llvmpipe executes both sides of a branch."""

from __future__ import annotations

HEADER = "#version 330 core\n"

# Key/fill/rim lights plus a sky/ground ambient, wrap diffuse for a soft skin look, Blinn specular.
# The skin evaluates the smooth terms (diffuse, ambient, rim) per vertex and only the specular per
# pixel: per-pixel diffuse cost a fifth of the frame on llvmpipe and looks the same on a face whose
# normals vary smoothly; the eyes light everything per pixel.
LIGHTING = """
const vec3 KEY_D = vec3(-0.4286, 0.5238, 0.7143);   // normalize(-0.45, 0.55, 0.75)
const vec3 FILL_D = vec3(0.7798, 0.0520, 0.6238);   // normalize(0.75, 0.05, 0.6)
const vec3 RIM_D = vec3(0.2873, 0.5747, -0.7663);   // normalize(0.3, 0.6, -0.8)
vec3 diffuse_light(vec3 n) {
    float key = max((dot(n, KEY_D) + 0.35) / 1.35, 0.0);
    float fill = max((dot(n, FILL_D) + 0.2) / 1.2, 0.0);
    vec3 sky = mix(vec3(0.16, 0.15, 0.14), vec3(0.30, 0.33, 0.38), 0.5 + 0.5 * n.y);
    return key * vec3(1.55, 1.45, 1.32) + fill * vec3(0.32, 0.37, 0.46) + sky;
}
vec3 rim_light(vec3 n, vec3 v) {
    float edge = 1.0 - max(dot(n, v), 0.0);
    return edge * edge * edge * max(dot(n, RIM_D) + 0.4, 0.0) * vec3(0.30, 0.32, 0.36);
}
vec3 specular(vec3 n, vec3 v, float spec, float shininess) {
    vec3 h = normalize(KEY_D + v);
    return spec * pow(max(dot(n, h), 0.0), shininess) * vec3(1.0, 0.97, 0.92) * float(dot(n, KEY_D) > 0.0);
}
vec3 specular32(vec3 n, vec3 v, float spec) {   // exponent 32 by squaring: no pow per pixel
    vec3 h = normalize(KEY_D + v);
    float x = max(dot(n, h), 0.0);
    x *= x; x *= x; x *= x; x *= x; x *= x;
    return spec * x * vec3(1.0, 0.97, 0.92);
}
vec3 light(vec3 albedo, vec3 n, vec3 p, float spec, float shininess) {
    vec3 v = normalize(-p);
    return albedo * diffuse_light(n) + rim_light(n, v) + specular(n, v, spec, shininess);
}
vec3 encode(vec3 c) {              // gamma 2.0: sqrt is far cheaper than pow on llvmpipe
    return sqrt(clamp(c, 0.0, 1.0));
}
vec3 ramp(float t) {                              // blue -> cyan -> green -> yellow -> red
    t = clamp(t, 0.0, 1.0);
    vec3 c = clamp(vec3(1.5 - abs(4.0 * t - 3.0), 1.5 - abs(4.0 * t - 2.0), 1.5 - abs(4.0 * t - 1.0)),
                   0.0, 1.0);
    return c;
}
"""

LIGHTING_RAMP_ONLY = LIGHTING[LIGHTING.index("vec3 ramp"):]

# The skin does everything smooth per vertex, so the pixel work is small: llvmpipe shades every
# pixel on the CPU, and it pays per pixel for every interpolated value (fewer varyings, fewer
# operations). Per vertex: the lit albedo (diffuse + ambient + rim), the Blinn half vector and the
# brow band's half width and strength along it. Per pixel: the brow edge (one smoothstep, crisp on
# a coarse mesh), a specular with exponent 32 by squaring, and the gamma encoding.
SKIN_VS = HEADER + LIGHTING + """
uniform mat4 mvp;
uniform mat4 view;
uniform float heat_scale;
in vec3 in_pos;
in vec3 in_normal;
in vec3 in_color;
in vec3 in_rest;
in vec2 in_brow;
out vec3 v_normal;
out vec3 v_half;
out vec3 v_lit;
#if defined(SKIN)
out vec3 v_brow;       // signed distance across the brow line, half width, strength
#if defined(SCALP)
uniform vec3 hair_albedo;
out vec3 v_hair;       // the lit hair (the scalp's in_brow: cm above the hairline, cm from the join)
#endif
#elif defined(HEAT)
out float v_disp;      // the colour map per pixel: interpolated colours would wash it out
out vec3 v_diffuse;
#endif
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    vec3 p = (view * vec4(in_pos, 1.0)).xyz;
    vec3 n = mat3(view) * in_normal;
    vec3 v = normalize(-p);
    vec3 diffuse = diffuse_light(n);
    v_normal = n;
    v_half = normalize(KEY_D + v);
#if defined(CLAY)
    vec3 albedo = vec3(0.36);
#elif defined(HEAT)
    vec3 albedo = vec3(0.0);
    v_disp = length(in_pos - in_rest) / heat_scale;
    v_diffuse = diffuse;
#elif defined(SCALP)
    vec3 albedo = in_color;
    v_brow = vec3(in_brow, 0.0);
    v_hair = hair_albedo * diffuse + rim_light(n, v);
#else
    vec3 albedo = in_color;
    // brow: a band across the brow line, thick at the inner end, thin and faded at the outer
    float u = in_brow.y;
    float half_w = mix(0.42, 0.16, clamp(u, 0.0, 1.0)) * smoothstep(-0.06, 0.05, u)
                   * (1.0 - smoothstep(0.95, 1.08, u));
    v_brow = vec3(in_brow.x - 0.1 * half_w, half_w, mix(0.95, 0.7, clamp(u, 0.0, 1.0)));
#endif
    v_lit = albedo * diffuse + rim_light(n, v);
}
"""

# Specialised by #define: SKIN (tinted skin: lips in the vertex colour, brows from the interpolated
# brow band), CLAY (pale, under muscles/trails so the lines read), HEAT (displacement colour map).
SKIN_FS = HEADER + LIGHTING_RAMP_ONLY + """
in vec3 v_normal;
in vec3 v_half;
in vec3 v_lit;
#if defined(SKIN)
in vec3 v_brow;
#if defined(SCALP)
in vec3 v_hair;
uniform vec3 hair_edge;  // the hairline's soft half width; the join's distance where hair starts, is full
#endif
#elif defined(HEAT)
in float v_disp;
in vec3 v_diffuse;
#endif
out vec4 frag;
void main() {
    vec3 c = v_lit;
#if defined(SCALP)
    // the hairline per pixel from two quantities that are near linear over a triangle: smooth and
    // sharp however coarse the head's mesh
    c = mix(c, v_hair, smoothstep(-hair_edge.x, hair_edge.x, v_brow.x)
                       * smoothstep(hair_edge.y, hair_edge.z, v_brow.y));
    const float spec = 0.12;
#elif defined(SKIN)
    float brow = (1.0 - smoothstep(0.4 * v_brow.y, v_brow.y + 1e-4, abs(v_brow.x))) * v_brow.z
                 * float(v_brow.y > 1e-3);
    c *= 1.0 - 0.91 * brow;    // brow hair: about a tenth of the skin's albedo in every channel
    const float spec = 0.12;
#elif defined(HEAT)
    vec3 albedo = ramp(v_disp);
    c += 0.6 * albedo * albedo * v_diffuse;
    const float spec = 0.05;
#else
    const float spec = 0.0;
#endif
#if !defined(CLAY)
    float x = max(dot(v_normal, v_half), 0.0) * inversesqrt(dot(v_normal, v_normal));
    x *= x; x *= x; x *= x; x *= x; x *= x;
    c += spec * x * vec3(1.0, 0.97, 0.92);
#endif
    // the inside of the mask, seen through an opening: dim, unlit
    frag = vec4(sqrt(clamp(gl_FrontFacing ? c : 0.3 * c, 0.0, 1.0)), 1.0);
}
"""

EYE_VS = HEADER + """
uniform mat4 mvp;
uniform mat4 view;
uniform mat3 rot;
uniform vec3 center;
uniform float radius;
in vec3 in_pos;
out vec3 v_local;
out vec3 v_pos;
out vec3 v_normal;
void main() {
    vec3 w = center + radius * (rot * in_pos);
    gl_Position = mvp * vec4(w, 1.0);
    v_local = in_pos;
    v_pos = (view * vec4(w, 1.0)).xyz;
    v_normal = mat3(view) * (rot * in_pos);
}
"""

# The gaze is +Z of the eyeball: iris and pupil are caps around it, sized like a human eye.
EYE_FS = HEADER + LIGHTING + """
in vec3 v_local;
in vec3 v_pos;
in vec3 v_normal;
out vec4 frag;
void main() {
    vec3 d = normalize(v_local);
    float ang = acos(clamp(d.z, -1.0, 1.0));
    float around = atan(d.y, d.x);
    vec3 sclera = vec3(0.72, 0.68, 0.64) * (1.0 - 0.15 * smoothstep(0.6, 1.6, ang));
    float streak = 0.75 + 0.25 * sin(around * 29.0) * sin(around * 7.0 + ang * 40.0);
    vec3 iris = vec3(0.16, 0.10, 0.05) * streak * mix(1.0, 0.45, smoothstep(0.40, 0.52, ang));
    vec3 col = mix(iris, sclera, smoothstep(0.50, 0.54, ang));
    col = mix(vec3(0.005), col, smoothstep(0.20, 0.23, ang));
    frag = vec4(encode(light(col, normalize(v_normal), v_pos, 0.9, 90.0)), 1.0);
}
"""

CAVITY_VS = HEADER + """
uniform mat4 mvp;
in vec3 in_pos;
in float in_depth;
in float in_teeth;
in vec3 in_rim;
out float v_depth;
out float v_teeth;
out vec3 v_rim;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_depth = in_depth;
    v_teeth = in_teeth;
    v_rim = in_rim;
}
"""

# All cavities in one draw: the rim colour and the teeth (mouth only) are vertex attributes; a teeth
# value above 1 brightens them (render.meshdata.Cavity's dentition, drawn for a head without teeth).
CAVITY_FS = HEADER + """
in float v_depth;
in float v_teeth;
in vec3 v_rim;
out vec4 frag;
void main() {
    vec3 c = mix(v_rim, vec3(0.004, 0.002, 0.002), smoothstep(0.0, 0.6, v_depth));
    c = mix(c, vec3(0.40, 0.38, 0.33) * (1.1 - v_depth) * max(v_teeth, 1.0), smoothstep(0.3, 0.6, v_teeth));
    frag = vec4(sqrt(c), 1.0);
}
"""

# Lines. `bias` pulls them towards the camera so lines lying on the skin win the depth test. Thick
# lines: a geometry shader widens each segment into a screen-space quad (core-profile line widths
# above 1 px are not portable). Trails: the vertex index tells the ring slot, hence the age.
LINE_VS = HEADER + """
uniform mat4 mvp;
uniform int trail_n;
uniform int trail_k;
uniform int trail_head;
uniform int trail_count;
uniform float bias;
in vec3 in_pos;
out vec4 g_color;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    gl_Position.z -= bias * gl_Position.w;
    g_color = vec4(1.0);
#ifdef TRAIL
    int slot = gl_VertexID / trail_n;
    int rel = (trail_head - slot + trail_k) % trail_k;    // 0 = newest sample
    float t = trail_count > 1 ? 1.0 - float(rel) / float(trail_count - 1) : 0.0;
    g_color = vec4(ramp(t), 1.0);
#endif
}
"""

LINE_GS = HEADER + """
layout(lines) in;
layout(triangle_strip, max_vertices = 4) out;
uniform vec2 viewport;
uniform float width;
in vec4 g_color[];
out vec4 f_color;
void main() {
    vec4 a = gl_in[0].gl_Position, b = gl_in[1].gl_Position;
    if (a.w <= 0.0 || b.w <= 0.0) return;
    vec2 sa = a.xy / a.w * viewport, sb = b.xy / b.w * viewport;
    vec2 dir = sb - sa;
    float len = length(dir);
    dir = len > 1e-4 ? dir / len : vec2(1.0, 0.0);
    vec2 off = vec2(-dir.y, dir.x) * width / viewport;
    f_color = g_color[0]; gl_Position = a + vec4(off * a.w, 0.0, 0.0); EmitVertex();
    f_color = g_color[0]; gl_Position = a - vec4(off * a.w, 0.0, 0.0); EmitVertex();
    f_color = g_color[1]; gl_Position = b + vec4(off * b.w, 0.0, 0.0); EmitVertex();
    f_color = g_color[1]; gl_Position = b - vec4(off * b.w, 0.0, 0.0); EmitVertex();
    EndPrimitive();
}
"""

LINE_FS = HEADER + """
uniform vec4 color;
#ifdef THIN
in vec4 g_color;
#define f_color g_color
#else
in vec4 f_color;
#endif
out vec4 frag;
void main() { frag = f_color * color; }
"""

# Dots for the nodes that did not move (their trail is empty); moving nodes are clipped away.
POINT_VS = HEADER + """
uniform mat4 mvp;
uniform float size;
uniform float still;
in vec3 in_pos;
in float in_path;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    gl_Position.z -= 1e-4 * gl_Position.w;
    if (in_path > still) gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    gl_PointSize = size;
}
"""

POINT_FS = HEADER + """
uniform vec4 color;
out vec4 frag;
void main() { frag = color; }
"""

POST_VS = HEADER + """
out vec2 v_uv;
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);   // one triangle covering the screen
    v_uv = p;
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
"""

# FXAA-style pass (after Lottes' FXAA: luma edge detection, then a blend along the edge direction
# with a guard against overshoot). Software GL runs every branch, so there is no early-out.
FXAA_FS = HEADER + """
uniform sampler2D scene;
uniform vec2 texel;
in vec2 v_uv;
out vec4 frag;
float luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }
void main() {
    vec3 m = texture(scene, v_uv).rgb;
    float lnw = luma(texture(scene, v_uv + texel * vec2(-1.0, -1.0)).rgb);
    float lne = luma(texture(scene, v_uv + texel * vec2(1.0, -1.0)).rgb);
    float lsw = luma(texture(scene, v_uv + texel * vec2(-1.0, 1.0)).rgb);
    float lse = luma(texture(scene, v_uv + texel * vec2(1.0, 1.0)).rgb);
    float lm = luma(m);
    float lo = min(lm, min(min(lnw, lne), min(lsw, lse)));
    float hi = max(lm, max(max(lnw, lne), max(lsw, lse)));
    vec2 dir = vec2((lsw + lse) - (lnw + lne), (lnw + lsw) - (lne + lse));
    float reduce = max((lnw + lne + lsw + lse) * 0.03125, 1.0 / 128.0);
    dir = clamp(dir / (min(abs(dir.x), abs(dir.y)) + reduce), vec2(-8.0), vec2(8.0)) * texel;
    vec3 a = 0.5 * (texture(scene, v_uv - dir / 6.0).rgb + texture(scene, v_uv + dir / 6.0).rgb);
    vec3 b = 0.5 * a + 0.25 * (texture(scene, v_uv - dir * 0.5).rgb + texture(scene, v_uv + dir * 0.5).rgb);
    float lb = luma(b);
    vec3 c = (lb < lo || lb > hi) ? a : b;
    frag = vec4(hi - lo < max(0.04, hi * 0.12) ? m : c, 1.0);
}
"""

# Supersample resolve: the mean of each SS x SS block. For SS = 2 one bilinear tap at the block's
# centre weighs its four texels equally, which is four times cheaper on a software rasterizer.
RESOLVE_FS = HEADER + """
uniform sampler2D scene;
in vec2 v_uv;
out vec4 frag;
void main() {
#if SS == 2
    frag = vec4(texture(scene, v_uv).rgb, 1.0);
#else
    ivec2 base = ivec2(gl_FragCoord.xy) * SS;
    vec3 acc = vec3(0.0);
    for (int j = 0; j < SS; ++j)
        for (int i = 0; i < SS; ++i) acc += texelFetch(scene, base + ivec2(i, j), 0).rgb;
    frag = vec4(acc / float(SS * SS), 1.0);
#endif
}
"""


HUD_VS = HEADER + """
uniform vec2 viewport;
in vec2 in_pos;
in vec2 in_uv;
in vec4 in_color;
out vec2 v_uv;
out vec4 v_color;
void main() {
    gl_Position = vec4(in_pos / viewport * vec2(2.0, -2.0) + vec2(-1.0, 1.0), 0.0, 1.0);
    v_uv = in_uv;
    v_color = in_color;
}
"""

HUD_FS = HEADER + """
uniform sampler2D atlas;
in vec2 v_uv;
in vec4 v_color;
out vec4 frag;
void main() {
    float a = v_uv.x < 0.0 ? 1.0 : texture(atlas, v_uv).r;
    frag = vec4(v_color.rgb, v_color.a * a);
}
"""


# The HUD's cached layer (premultiplied RGBA, the size of the viewport) composited over the frame:
# one texel per pixel, so texelFetch at the pixel's own position (no filtering, no uv varying).
HUD_LAYER_VS = HEADER + """
uniform vec2 viewport;
in vec2 in_pos;
void main() {
    gl_Position = vec4(in_pos / viewport * vec2(2.0, -2.0) + vec2(-1.0, 1.0), 0.0, 1.0);
}
"""

HUD_LAYER_FS = HEADER + """
uniform sampler2D layer;
uniform ivec2 origin;
out vec4 frag;
void main() {
    frag = texelFetch(layer, ivec2(gl_FragCoord.xy) - origin, 0);
}
"""


def skin_source(kind: str, vertex: bool = False) -> str:
    """The skin fragment (or vertex) shader for kind "SKIN", "CLAY", "HEAT" or "SCALP" (the held
    head's skin and hair: SKIN with the hair drawn from the hairline coordinates in in_brow)."""
    defs = "#define SKIN\n#define SCALP\n" if kind == "SCALP" else f"#define {kind}\n"
    return (SKIN_VS if vertex else SKIN_FS).replace(HEADER, HEADER + defs, 1)


def resolve_source(ss: int) -> str:
    return RESOLVE_FS.replace(HEADER, HEADER + f"#define SS {int(ss)}\n", 1)


def line_program_sources(thick: bool = False, trail: bool = False) -> dict[str, str]:
    """Sources for a line program: thick (widened by the geometry shader, costly on llvmpipe, for
    the few muscle lines) or thin native 1-px lines (wireframe, trails)."""
    defs = ("#define TRAIL\n" if trail else "") + ("" if thick else "#define THIN\n")

    def spec(src: str) -> str:
        return src.replace(HEADER, HEADER + defs, 1)

    out = {"vertex_shader": spec(LINE_VS.replace(HEADER, HEADER + LIGHTING_RAMP_ONLY, 1)),
           "fragment_shader": spec(LINE_FS)}
    if thick:
        out["geometry_shader"] = spec(LINE_GS)
    return out

