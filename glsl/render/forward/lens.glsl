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

// lens_brown_conrady(u0 + du) - lens_brown_conrady(u0) without subtracting the two: the
// polynomials' differences by divided differences in q = r^2, the rational factor's by
// (dN D0 - N0 dD) / (D1 D0), the products' by (a + da)(b + db) - ab = da (b + db) + a db.
vec2 lens_brown_conrady_offset(vec4 ka, vec4 kb, vec2 u0, vec2 du) {
    vec2 u1 = u0 + du;
    float q0 = dot(u0, u0), q1 = dot(u1, u1);
    float dq = du.x * (2.0 * u0.x + du.x) + du.y * (2.0 * u0.y + du.y);
    float s2 = q1 + q0, s3 = q1 * q1 + q1 * q0 + q0 * q0;
    float n0 = 1.0 + q0 * (ka.x + q0 * (ka.y + q0 * ka.z));
    float d0 = 1.0 + q0 * (ka.w + q0 * (kb.x + q0 * kb.y));
    float n1 = 1.0 + q1 * (ka.x + q1 * (ka.y + q1 * ka.z));
    float d1 = 1.0 + q1 * (ka.w + q1 * (kb.x + q1 * kb.y));
    float dn = dq * (ka.x + ka.y * s2 + ka.z * s3);
    float dd = dq * (ka.w + kb.x * s2 + kb.y * s3);
    float r1 = n1 / d1;
    float dr = (dn * d0 - n0 * dd) / (d1 * d0);
    float p1 = kb.z, p2 = kb.w;
    float dxy = du.x * u1.y + u0.x * du.y;
    return vec2(du.x * r1 + u0.x * dr + 2.0 * p1 * dxy + p2 * (dq + 2.0 * du.x * (2.0 * u0.x + du.x)),
                du.y * r1 + u0.y * dr + p1 * (dq + 2.0 * du.y * (2.0 * u0.y + du.y)) + 2.0 * p2 * dxy);
}

// lens::wrap_angle: a in (-PI, PI].
float lens_wrap_angle(float a) {
    float t = mod(a, LENS_TAU);
    return t > LENS_PI ? t - LENS_TAU : t;
}

// atan(y, x) in [-PI, PI] to a few f32 ulps: lavapipe's own atan is off by about 2e-5
// relative, which moved conics through the angle lenses by 4e-5 from the f64 reference.
// The ratio of the smaller to the larger magnitude is taken to at most tan(PI / 12) by
// atan(t) = PI / 6 + atan((sqrt(3) t - 1) / (sqrt(3) + t)), where the series to t^11 is
// good to 1e-8 relative; then the octant and quadrant. 0 at the origin.
float lens_atan(float y, float x) {
    float ax = abs(x), ay = abs(y);
    float hi = max(ax, ay);
    if (hi == 0.0) return 0.0;
    float t = min(ax, ay) / hi;
    float base = 0.0;
    const float SQRT3 = 1.7320508075688772;
    if (t > 0.2679491924311227) {
        t = (SQRT3 * t - 1.0) / (SQRT3 + t);
        base = LENS_PI / 6.0;
    }
    float t2 = t * t;
    float r = base + t * (1.0 + t2 * (-1.0 / 3.0 + t2 * (1.0 / 5.0 + t2 * (-1.0 / 7.0
        + t2 * (1.0 / 9.0 - t2 * (1.0 / 11.0))))));
    if (ay > ax) r = 0.5 * LENS_PI - r;
    if (x < 0.0) r = LENS_PI - r;
    return y < 0.0 ? -r : r;
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
        float theta = lens_atan(r, p.z);
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
        float lon = middle + lens_wrap_angle(lens_atan(p.x, p.z) - middle);
        float lat = lens_atan(-p.y, length(p.xz));
        float u = (lon - ka.x) / (ka.y - ka.x);
        float v = (lat - ka.z) / (ka.w - ka.z);
        pixel = vec2(u * float(params.image.x), v * float(params.image.y));
        return true;
    }
    default:
        return false;
    }
}

// Whether the lens images camera-space point p: lens_project's test alone, without the
// pixel (the unscented transform asks it of every sigma point).
bool lens_images(vec3 p) {
    switch (params.modes.y) {
    case LENS_RADIAL_TANGENTIAL: {
        if (p.z <= 0.0) return false;
        vec2 u = p.xy / p.z;
        return dot(u, u) < params.lens_c.y;
    }
    case LENS_FISHEYE:
        return dot(p, p) != 0.0 && lens_atan(length(p.xy), p.z) <= params.lens_b.x;
    case LENS_ORTHOGRAPHIC:
        return p.z > 0.0;
    case LENS_EQUIRECTANGULAR:
        return dot(p, p) != 0.0;
    default:
        return false;
    }
}

// The pixel of p0 + step minus the pixel of p0 (both imaged), in a form without the
// cancellation of subtracting the two pixels: the angles are differenced by atan of a
// cross and a dot product, the distortion by lens_brown_conrady_offset, the radii by (r1^2 - r0^2) / (r1 + r0), the fisheye's
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
        return f.xy * lens_brown_conrady_offset(ka, kb, u0, du);
    }
    case LENS_FISHEYE: {
        float r0 = length(p0.xy), r1 = length(p1.xy);
        float theta0 = lens_atan(r0, p0.z);
        if (r0 == 0.0 || r1 == 0.0) {
            // On the axis: one of the two pixels is the principal point.
            vec2 e0 = r0 == 0.0 ? vec2(0.0) : p0.xy / r0;
            vec2 e1 = r1 == 0.0 ? vec2(0.0) : p1.xy / r1;
            float theta1 = lens_atan(r1, p1.z);
            return f.xy * (lens_equidistant(ka, theta1) * e1 - lens_equidistant(ka, theta0) * e0);
        }
        float dr = (step.x * (2.0 * p0.x + step.x) + step.y * (2.0 * p0.y + step.y)) / (r1 + r0);
        float dtheta = lens_atan(dr * p0.z - step.z * r0, r1 * r0 + p1.z * p0.z);
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
        float dlon = cross_lon == 0.0 && dot_lon == 0.0 ? 0.0 : lens_atan(cross_lon, dot_lon);
        float dh = h1 + h0 == 0.0 ? 0.0
            : (step.x * (2.0 * p0.x + step.x) + step.z * (2.0 * p0.z + step.z)) / (h1 + h0);
        float dlat = lens_atan(-step.y * h0 + p0.y * dh, h1 * h0 + p1.y * p0.y);
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
        imaged = imaged && lens_images(mean + step) && lens_images(mean - step);
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

// The equidistant map's slope d/dtheta (distortion::equidistant_slope).
float lens_equidistant_slope(vec4 k, float theta) {
    float t2 = theta * theta;
    return 1.0 + t2 * (3.0 * k.x + t2 * (5.0 * k.y + t2 * (7.0 * k.z + t2 * 9.0 * k.w)));
}

// The Jacobian of lens_brown_conrady at pinhole coordinates (x, y) (symmetric;
// lens::brown_conrady_jacobian).
mat2 lens_brown_conrady_jacobian(vec4 ka, vec4 kb, float x, float y) {
    float q = x * x + y * y;
    float n = 1.0 + q * (ka.x + q * (ka.y + q * ka.z));
    float d = 1.0 + q * (ka.w + q * (kb.x + q * kb.y));
    float dn = ka.x + q * (2.0 * ka.y + q * 3.0 * ka.z);
    float dd = ka.w + q * (2.0 * kb.x + q * 3.0 * kb.y);
    float r = n / d;
    // dR / d(r^2).
    float dr = (dn * d - n * dd) / (d * d);
    float p1 = kb.z, p2 = kb.w;
    float xx = r + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x;
    float xy = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y;
    float yy = r + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x;
    return mat2(xx, xy, xy, yy);
}

// The Jacobian of lens_project at a point p it images: column i is the pixel's
// derivative along p's axis i (lens::Lens::jacobian, in f32).
mat3x2 lens_jacobian(vec3 p) {
    vec4 f = params.focal;
    vec4 ka = params.lens_a, kb = params.lens_b;
    switch (params.modes.y) {
    case LENS_RADIAL_TANGENTIAL: {
        float z = p.z;
        float x = p.x / z, y = p.y / z;
        // d(x / z, y / z) / d(x, y, z), then the distortion's, then the focal lengths.
        mat3x2 dn = mat3x2(vec2(1.0 / z, 0.0), vec2(0.0, 1.0 / z), vec2(-x / z, -y / z));
        return mat2(f.x, 0.0, 0.0, f.y) * lens_brown_conrady_jacobian(ka, kb, x, y) * dn;
    }
    case LENS_FISHEYE: {
        float r = length(p.xy);
        if (r == 0.0) {
            // On the axis: theta = r / z to first order, and the slope at 0 is 1.
            return mat3x2(vec2(f.x / p.z, 0.0), vec2(0.0, f.y / p.z), vec2(0.0));
        }
        float rho2 = r * r + p.z * p.z;
        float theta = lens_atan(r, p.z);
        float g = lens_equidistant(ka, theta);
        float dg = lens_equidistant_slope(ka, theta);
        vec3 dtheta = vec3(p.z * p.x / (r * rho2), p.z * p.y / (r * rho2), -r / rho2);
        vec3 dr = vec3(p.x / r, p.y / r, 0.0);
        float s = g / r;
        vec3 ds = (dg * dtheta * r - g * dr) / (r * r);
        // pixel = f (x s, y s) + c.
        vec3 row_x = f.x * (vec3(s, 0.0, 0.0) + p.x * ds);
        vec3 row_y = f.y * (vec3(0.0, s, 0.0) + p.y * ds);
        return mat3x2(vec2(row_x.x, row_y.x), vec2(row_x.y, row_y.y), vec2(row_x.z, row_y.z));
    }
    case LENS_ORTHOGRAPHIC:
        return mat3x2(vec2(f.x, 0.0), vec2(0.0, f.y), vec2(0.0));
    case LENS_EQUIRECTANGULAR: {
        float xz = p.x * p.x + p.z * p.z;
        float h = sqrt(xz);
        float l2 = p.y * p.y + xz;
        vec3 dlon = vec3(p.z / xz, 0.0, -p.x / xz);
        // lat = atan(-y, h): d/dy = -h / l2, d/dh = y / l2, dh = (x, z) / h.
        vec3 dlat = vec3(p.y / l2 * p.x / h, -h / l2, p.y / l2 * p.z / h);
        vec3 u = float(params.image.x) / (ka.y - ka.x) * dlon;
        vec3 v = float(params.image.y) / (ka.w - ka.z) * dlat;
        return mat3x2(vec2(u.x, v.x), vec2(u.y, v.y), vec2(u.z, v.z));
    }
    default:
        return mat3x2(0.0);
    }
}

// The chain rule through lens_unscented of a Gaussian it projected (cpu::backward's lens
// module, in f32): from dL/d mean pixel and dL/d covariance (xx, xy, yy; the xy entry
// counted once) to dL/d mean and dL/d axes, in camera space. With e_j the sigma points'
// pixels less the mean: dL/de_j = wc_j (G + G^T) e_j; dL/du_j = dL/de_j + wm_j (dL/dmu -
// sum_k dL/de_k); dL/dp_j = J_j^T dL/du_j; the mean takes every dL/dp_j, axis i
// spread * (dL/dp_(+i) - dL/dp_(-i)).
void lens_unscented_backward(vec3 mean, mat3 axes, vec2 g_mean, vec3 g_cov,
                             out vec3 g_v, out mat3 g_axes) {
    vec4 ut = params.unscented;
    vec2 d[7];
    vec3 p[7];
    d[0] = vec2(0.0);
    p[0] = mean;
    for (int i = 0; i < 3; i++) {
        vec3 step = ut.x * axes[i];
        d[1 + 2 * i] = lens_offset(mean, step);
        d[2 + 2 * i] = lens_offset(mean, -step);
        p[1 + 2 * i] = mean + step;
        p[2 + 2 * i] = mean - step;
    }
    vec2 shift = vec2(0.0);
    for (int j = 1; j < 7; j++) shift += ut.z * d[j];
    vec2 g_e[7];
    vec2 g_e_sum = vec2(0.0);
    for (int j = 0; j < 7; j++) {
        vec2 e = d[j] - shift;
        float w = j == 0 ? ut.w : ut.z;
        g_e[j] = w * vec2(2.0 * g_cov.x * e.x + g_cov.y * e.y, g_cov.y * e.x + 2.0 * g_cov.z * e.y);
        g_e_sum += g_e[j];
    }
    vec2 g_mu = g_mean - g_e_sum;
    vec3 g_p[7];
    g_v = vec3(0.0);
    for (int j = 0; j < 7; j++) {
        float w = j == 0 ? ut.y : ut.z;
        g_p[j] = transpose(lens_jacobian(p[j])) * (g_e[j] + w * g_mu);
        g_v += g_p[j];
    }
    for (int i = 0; i < 3; i++) g_axes[i] = ut.x * (g_p[1 + 2 * i] - g_p[2 + 2 * i]);
}

#endif
