"""GLSL for the scanned head (render.scan_draw): its skin (and, by material, the mouth's inside and the
lashes) and its eyeballs. Smooth terms per vertex, edges and highlights per pixel, as for the
procedural face (render.shaders): llvmpipe pays per pixel for every varying and operation."""

from __future__ import annotations

from render.shaders import HEADER, LIGHTING, LIGHTING_RAMP_ONLY

# Per vertex: the light (key with a wider, redder wrap for the light scattered under the skin;
# fill; sky; rim), the baked occlusion times the fold term of this frame, the albedo; a fold term
# beyond 1 (never a fold's: they stay under 0.5) is a cast shadow, the key light and the highlight
# taken down by what lies past 1 (at most 0.85; the closing lids' seam, render.scan_seam). Per pixel:
# the vermilion and the brows' edges from their interpolated signed distances (cm), the brows'
# hair from the face chart's coordinates, and a Blinn highlight, glossier on the lips (PLAIN: the
# highlight per vertex too).
SCAN_SKIN_VS = HEADER + LIGHTING + """
uniform mat4 mvp;
uniform mat4 view;
uniform float heat_scale;
in vec3 in_pos;
in vec3 in_normal;
in float in_fold;
in vec3 in_albedo;
in vec4 in_mat;
in vec2 in_uv;
in vec3 in_rest;
out vec3 v_lit;
#if !defined(PLAIN)
out vec3 v_normal;
out vec3 v_half;
out vec4 v_mat;
out vec2 v_uv;
#endif
#if defined(HEAT)
out float v_disp;
#endif
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    vec3 p = (view * vec4(in_pos, 1.0)).xyz;
    vec3 n = mat3(view) * in_normal;
    vec3 v = normalize(-p);
    float fold = clamp(1.0 - 1.8 * max(in_fold, 0.0), 0.3, 1.0) * (1.0 + 0.25 * clamp(-in_fold, 0.0, 0.3));
    float occ = in_mat.z * fold;
    float shaded = 1.0 - clamp(in_fold - 1.0, 0.0, 0.85);  // a fold term past 1: the key light shaded
    float k = dot(n, KEY_D);
    vec3 key = vec3(max((k + 0.55) / 1.55, 0.0), max((k + 0.3) / 1.3, 0.0), max((k + 0.25) / 1.25, 0.0));
    key *= key * shaded;                         // a softer terminator, red reaching furthest
    float fill = max((dot(n, FILL_D) + 0.2) / 1.2, 0.0);
    vec3 sky = mix(vec3(0.13, 0.12, 0.11), vec3(0.30, 0.32, 0.36), 0.5 + 0.5 * n.y);
    vec3 light = key * vec3(1.75, 1.62, 1.48) * mix(1.0, occ, 0.55) + (fill * vec3(0.30, 0.34, 0.42) + sky) * occ;
#if defined(CLAY)
    vec3 albedo = vec3(0.36);
#elif defined(HEAT)
    vec3 albedo = vec3(0.05);
    v_disp = length(in_pos - in_rest) / heat_scale;
#else
    vec3 albedo = in_albedo;
#endif
    v_lit = albedo * light + rim_light(n, v) * occ * albedo * 1.6;
#if defined(PLAIN)
    float x = max(dot(n, normalize(KEY_D + v)), 0.0) * inversesqrt(dot(n, n));
    x *= x; x *= x; x *= x; x *= x; x *= x;
    v_lit += in_mat.w * occ * shaded * x * vec3(1.0, 0.97, 0.92);
#else
    v_normal = n;
    v_half = normalize(KEY_D + v);
    v_mat = vec4(in_mat.xy, in_mat.w * occ * shaded, occ);
    v_uv = in_uv;
#endif
}
"""

# The skin away from the brows and the vermilion (nine tenths of its triangles, most of its pixels):
# SCAN_SKIN_FS's light without its brow or lip terms (exactly 0 on these triangles), and its
# highlight taken per vertex (the same Blinn term, interpolated across the triangle): one vec3
# interpolated instead of ten values. llvmpipe pays for each interpolated value in every triangle's
# set-up and every pixel; on the scan's small triangles (a few pixels each at 720p) the picture
# changes by at most a few levels where the highlight is sharpest (docs/rendering.md).
SCAN_PLAIN_FS = HEADER + """
in vec3 v_lit;
out vec4 frag;
void main() {
    frag = vec4(sqrt(clamp(v_lit, 0.0, 1.0)), 1.0);
}
"""

SCAN_SKIN_FS = HEADER + LIGHTING_RAMP_ONLY + """
in vec3 v_normal;
in vec3 v_half;
in vec3 v_lit;
in vec4 v_mat;
in vec2 v_uv;
#if defined(HEAT)
in float v_disp;
#endif
out vec4 frag;
void main() {
    vec3 c = v_lit;
    float spec = v_mat.z;
#if defined(SKIN)
    // the vermilion: a soft edge about half a millimetre wide
    float lip = 1.0 - smoothstep(-0.05, 0.05, v_mat.y);
    c *= mix(vec3(1.0), vec3(0.80, 0.45, 0.50), lip);
    // brow hair: strands along the brow (slanted up and out), breaking up the border
    // two triangle waves (cheaper than sines on a software rasterizer): hairs slanted up and out
    float side = v_uv.x < 0.5 ? -1.0 : 1.0;
    float s = (abs(fract(143.0 * (v_uv.y - 0.55 * side * (v_uv.x - 0.5))) - 0.5) * 4.0 - 1.0)
              * (abs(fract(27.5 * v_uv.x + 6.4 * v_uv.y) - 0.5) * 4.0 - 1.0);
    float brow = (1.0 - smoothstep(-0.12, 0.06, v_mat.x + 0.07 * s)) * (0.9 + 0.1 * s);
    c *= 1.0 - 0.93 * brow;
    spec = spec * (1.0 - brow) + 0.12 * lip * v_mat.w;
#elif defined(HEAT)
    vec3 h = ramp(v_disp);
    c += 0.55 * h * h * v_mat.w;
    spec = 0.05;
#else
    spec = 0.0;
#endif
    float x = max(dot(v_normal, v_half), 0.0) * inversesqrt(dot(v_normal, v_normal));
    x *= x; x *= x; x *= x; x *= x; x *= x;
    c += spec * x * vec3(1.0, 0.97, 0.92);
    frag = vec4(sqrt(clamp(gl_FrontFacing ? c : 0.3 * c, 0.0, 1.0)), 1.0);
}
"""

# The eyeballs: the sclera, a textured iris and the pupil from each vertex's angle to the gaze axis
# at rest (so they turn with the eyeball however the eye is posed), the shadow of the upper lid,
# the shadow of lids shut over it (its rows' fold term, render.scan_seam), and the cornea's wet
# highlights (a sharp one from the key light, a broad one from the fill).
SCAN_EYE_VS = HEADER + """
uniform mat4 mvp;
uniform mat4 view;
in vec3 in_pos;
in vec3 in_normal;
in float in_angle;
in vec2 in_uv;
in float in_fold;
out vec3 v_pos;
out vec3 v_normal;
out float v_angle;
out float v_up;
out vec2 v_uv;
out float v_open;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_open = 1.0 - 0.85 * clamp(in_fold, 0.0, 1.0);  // the eye shut: its seam's shadow (render.scan_seam)
    v_pos = (view * vec4(in_pos, 1.0)).xyz;
    v_normal = mat3(view) * in_normal;
    v_angle = in_angle;
    v_up = in_normal.y;
    v_uv = in_uv - 0.5;
}
"""

SCAN_EYE_FS = HEADER + LIGHTING + """
uniform float iris_angle;
uniform float pupil_angle;
in vec3 v_pos;
in vec3 v_normal;
in float v_angle;
in float v_up;
in vec2 v_uv;
in float v_open;
out vec4 frag;
void main() {
    float a = v_angle;
    float around = atan(v_uv.y, v_uv.x);
    vec3 sclera = vec3(0.62, 0.57, 0.52) * (1.0 - 0.25 * smoothstep(0.8, 1.6, a));
    float ring = 0.72 + 0.28 * sin(around * 31.0) * sin(around * 7.0 + a * 50.0);
    vec3 iris = mix(vec3(0.05, 0.032, 0.018), vec3(0.20, 0.12, 0.06), smoothstep(pupil_angle, iris_angle, a)) * ring;
    iris *= 1.0 - 0.55 * smoothstep(iris_angle - 0.08, iris_angle, a);       // the limbal ring
    vec3 col = mix(iris, sclera, smoothstep(iris_angle - 0.01, iris_angle + 0.03, a));
    col = mix(vec3(0.004), col, smoothstep(pupil_angle - 0.015, pupil_angle + 0.015, a));
    vec3 n = normalize(v_normal);
    vec3 v = normalize(-v_pos);
    float lid = 1.0 - 0.55 * smoothstep(0.15, 0.75, v_up);                    // the upper lid's shadow
    vec3 c = col * diffuse_light(n) * lid;
    c += specular(n, v, 1.6, 180.0);
    vec3 h2 = normalize(FILL_D + v);
    c += 0.25 * pow(max(dot(n, h2), 0.0), 60.0) * vec3(0.85, 0.9, 1.0);
    frag = vec4(encode(c * v_open), 1.0);
}
"""


# The lashes: the scan's lash strips (three layered strips of six rows per lid) blended over the
# face, dark hair strands along the lid thinning to the tips.
SCAN_LASH_VS = HEADER + """
uniform mat4 mvp;
in vec3 in_pos;
in vec2 in_uv;
out vec2 v_uv;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_uv = in_uv;
}
"""

SCAN_LASH_FS = HEADER + """
in vec2 v_uv;
out vec4 frag;
void main() {
    float strand = 0.1 + 1.8 * abs(fract(v_uv.x * 207.0) - 0.5);
    float lower = step(1.5, v_uv.x);
    float a = mix(0.8, 0.3, lower) * strand * (1.0 - smoothstep(mix(0.2, 0.0, lower), mix(1.0, 0.6, lower), v_uv.y));
    frag = vec4(vec3(0.10, 0.085, 0.075), a);
}
"""


def scan_skin_source(kind: str, vertex: bool = False) -> str:
    """The scanned head's skin shader for kind "SKIN" (materials), "CLAY" or "HEAT", or "PLAIN"
    (the skin's triangles without brow or vermilion: SKIN's look, less work per pixel)."""
    src = SCAN_SKIN_VS if vertex else (SCAN_PLAIN_FS if kind == "PLAIN" else SCAN_SKIN_FS)
    return src.replace(HEADER, HEADER + f"#define {kind}\n", 1)
