// The camera's lens, for preprocess: the exact map from a camera-space point to its
// pixel (core::camera::lens::Lens::project, in f32) and the projection of a Gaussian
// through it by the unscented transform (core::model::unscented::project, which sums
// the same way). Reads the frame's `params` (FrameParams): the lens is `modes.y`
// (LENS_*), its coefficients `lens_a`, `lens_b` and `lens_c`, the transform's weights
// `unscented`.
#ifndef VERISPLAT_LENS_GLSL
#define VERISPLAT_LENS_GLSL

const float LENS_PI = 3.14159265358979;
const float LENS_TAU = 6.28318530717959;

// distortion::equidistant: theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8).
float lens_equidistant(vec4 k, float theta) {
    float t2 = theta * theta;
    return theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))));
}

// distortion::brown_conrady of pinhole coordinates p: radial k1..k6 (ka, kb.xy),
// tangential p1, p2 (kb.zw).
vec2 lens_brown_conrady(vec4 ka, vec4 kb, vec2 p) {
    float x = p.x, y = p.y;
    float r2 = x * x + y * y;
    float num = 1.0 + r2 * (ka.x + r2 * (ka.y + r2 * ka.z));
    float den = 1.0 + r2 * (ka.w + r2 * (kb.x + r2 * kb.y));
    float radial = num / den;
    return vec2(x * radial + 2.0 * kb.z * x * y + kb.w * (r2 + 2.0 * x * x),
                y * radial + kb.z * (r2 + 2.0 * y * y) + 2.0 * kb.w * x * y);
}

// lens::wrap_angle: a in (-PI, PI].
float lens_wrap_angle(float a) {
    float t = mod(a, LENS_TAU);
    return t > LENS_PI ? t - LENS_TAU : t;
}

// Whether the lens images camera-space point p, and if so its pixel (pixel centres at
// i + 0.5). The pinhole is not handled here (preprocess projects it by the EWA rule).
bool lens_project(vec3 p, out vec2 pixel) {
    vec4 f = params.focal;
    vec4 ka = params.lens_a, kb = params.lens_b;
    pixel = vec2(0.0);
    switch (params.modes.y) {
    case LENS_RADIAL_TANGENTIAL:
        if (p.z <= 0.0) return false;
        vec2 u = p.xy / p.z;
        // At or past the fold the polynomial sends points back inside: not imaged.
        if (dot(u, u) >= params.lens_c.y) return false;
        pixel = f.xy * lens_brown_conrady(ka, kb, u) + f.zw;
        return true;
    case LENS_FISHEYE: {
        float r = length(p.xy);
        if (dot(p, p) == 0.0) return false;
        float theta = atan(r, p.z);
        if (theta > kb.x) return false;
        if (r == 0.0) {
            pixel = f.zw;
            return true;
        }
        float s = lens_equidistant(ka, theta) / r;
        pixel = f.xy * (p.xy * s) + f.zw;
        return true;
    }
    case LENS_ORTHOGRAPHIC:
        if (p.z <= 0.0) return false;
        pixel = f.xy * p.xy + f.zw;
        return true;
    case LENS_EQUIRECTANGULAR: {
        if (dot(p, p) == 0.0) return false;
        // The longitude's turn nearest the window's middle.
        float middle = 0.5 * (ka.x + ka.y);
        float lon = middle + lens_wrap_angle(atan(p.x, p.z) - middle);
        float lat = atan(-p.y, length(p.xz));
        float u = (lon - ka.x) / (ka.y - ka.x);
        float v = (lat - ka.z) / (ka.w - ka.z);
        pixel = vec2(u * float(params.image.x), v * float(params.image.y));
        return true;
    }
    default:
        return false;
    }
}

// The pixel of p0 + step minus the pixel of p0 (both imaged), in a form without the
// cancellation of subtracting the two pixels: the angles are differenced by atan of a
// cross and a dot product, the radii by (r1^2 - r0^2) / (r1 + r0), the fisheye's
// polynomial by divided differences. The same numbers as the CPU's difference of the
// two pixels (which it takes in f64), to f32 rounding; an equirectangular difference of
// longitudes is on the turn nearest zero.
vec2 lens_offset(vec3 p0, vec3 step) {
    vec4 f = params.focal;
    vec4 ka = params.lens_a, kb = params.lens_b;
    vec3 p1 = p0 + step;
    switch (params.modes.y) {
    case LENS_RADIAL_TANGENTIAL: {
        vec2 u0 = p0.xy / p0.z;
        vec2 du = (step.xy * p0.z - p0.xy * step.z) / (p1.z * p0.z);
        return f.xy * (lens_brown_conrady(ka, kb, u0 + du) - lens_brown_conrady(ka, kb, u0));
    }
    case LENS_FISHEYE: {
        float r0 = length(p0.xy), r1 = length(p1.xy);
        float theta0 = atan(r0, p0.z);
        if (r0 == 0.0 || r1 == 0.0) {
            // On the axis: one of the two pixels is the principal point.
            vec2 e0 = r0 == 0.0 ? vec2(0.0) : p0.xy / r0;
            vec2 e1 = r1 == 0.0 ? vec2(0.0) : p1.xy / r1;
            float theta1 = atan(r1, p1.z);
            return f.xy * (lens_equidistant(ka, theta1) * e1 - lens_equidistant(ka, theta0) * e0);
        }
        float dr = (step.x * (2.0 * p0.x + step.x) + step.y * (2.0 * p0.y + step.y)) / (r1 + r0);
        float dtheta = atan(dr * p0.z - step.z * r0, r1 * r0 + p1.z * p0.z);
        float theta1 = theta0 + dtheta;
        // g(theta1) - g(theta0) = dtheta (1 + k1 S3 + k2 S5 + k3 S7 + k4 S9), S_n the
        // divided difference of theta^n: S_(n+1) = theta1 S_n + theta0^n.
        float sn = 1.0, t0n = theta0;
        float sums[4];
        for (int n = 1; n < 9; n++) {
            sn = theta1 * sn + t0n;
            t0n *= theta0;
            if (n == 2) sums[0] = sn;
            if (n == 4) sums[1] = sn;
            if (n == 6) sums[2] = sn;
            if (n == 8) sums[3] = sn;
        }
        float dg = dtheta * (1.0 + ka.x * sums[0] + ka.y * sums[1] + ka.z * sums[2] + ka.w * sums[3]);
        float g0 = lens_equidistant(ka, theta0);
        vec2 e1 = p1.xy / r1;
        vec2 de = (step.xy * r0 - p0.xy * dr) / (r1 * r0);
        return f.xy * (dg * e1 + g0 * de);
    }
    case LENS_ORTHOGRAPHIC:
        return f.xy * step.xy;
    case LENS_EQUIRECTANGULAR: {
        float h0 = length(p0.xz), h1 = length(p1.xz);
        float cross_lon = step.x * p0.z - step.z * p0.x;
        float dot_lon = p1.x * p0.x + p1.z * p0.z;
        float dlon = cross_lon == 0.0 && dot_lon == 0.0 ? 0.0 : atan(cross_lon, dot_lon);
        float dh = h1 + h0 == 0.0 ? 0.0
            : (step.x * (2.0 * p0.x + step.x) + step.z * (2.0 * p0.z + step.z)) / (h1 + h0);
        float dlat = atan(-step.y * h0 + p0.y * dh, h1 * h0 + p1.y * p0.y);
        return vec2(dlon * float(params.image.x) / (ka.y - ka.x),
                    dlat * float(params.image.y) / (ka.w - ka.z));
    }
    default:
        return vec2(0.0);
    }
}

// The unscented projection of the camera-space Gaussian with mean `mean` and scaled axes
// `axes` (columns, R S): false when culled (a sigma point the lens does not image, or
// every one further outside the image than the margin); else the mean pixel and the
// covariance (xx, xy, yy) in pixels, before the rules' dilation. As the CPU, the sums
// are taken relative to the centre's pixel.
bool lens_unscented(vec3 mean, mat3 axes, out vec2 mean_px, out vec3 cov) {
    vec4 ut = params.unscented;
    mean_px = vec2(0.0);
    cov = vec3(0.0);
    vec2 centre;
    if (!lens_project(mean, centre)) return false;
    vec2 d[6];
    bool imaged = true;
    for (int i = 0; i < 3; i++) {
        vec3 step = ut.x * axes[i];
        vec2 unused;
        imaged = imaged && lens_project(mean + step, unused) && lens_project(mean - step, unused);
        d[2 * i] = lens_offset(mean, step);
        d[2 * i + 1] = lens_offset(mean, -step);
    }
    if (!imaged) return false;
    vec2 size = vec2(params.image.xy);
    vec2 margin = params.lens_c.x * size;
    bool in_view = all(greaterThanEqual(centre, -margin)) && all(lessThanEqual(centre, size + margin));
    for (int i = 0; i < 6; i++) {
        vec2 p = centre + d[i];
        in_view = in_view || (all(greaterThanEqual(p, -margin)) && all(lessThanEqual(p, size + margin)));
    }
    if (!in_view) return false;
    vec2 shift = vec2(0.0);
    for (int i = 0; i < 6; i++) shift += ut.z * d[i];
    vec3 c = ut.w * vec3(shift.x * shift.x, shift.x * shift.y, shift.y * shift.y);
    for (int i = 0; i < 6; i++) {
        vec2 e = d[i] - shift;
        c += ut.z * vec3(e.x * e.x, e.x * e.y, e.y * e.y);
    }
    mean_px = centre + shift;
    cov = c;
    return true;
}

#endif
