/* Cameras that orbit the origin, and the crop between a full render and the model image.
 *
 * Conventions (glTF): world is y-up, the mesh's front is its +z side. A camera at azimuth a,
 * elevation e sits at r * (cos e sin a, sin e, cos e cos a) and looks at the origin, so
 * azimuth 0 is the front view (looking along -z), azimuth 180 the back view, azimuth 90
 * looks at the +x side, elevation 90 looks down from the top.
 * Image space: pixel (x, y) covers [x, x+1) x [y, y+1), row 0 at the top, centres at +0.5.
 * Depth is the distance along the viewing axis (positive in front of the camera). */
#ifndef MX_CAMERA_H
#define MX_CAMERA_H

#include "../../runtime/status.h"
#include "../../runtime/threadpool.h"
#include "image.h"

typedef struct mx_camera {
    int ortho;              /* 1: orthographic, 0: perspective */
    float azimuth, elevation; /* degrees */
    float radius;           /* distance of the eye from the origin */
    float half_extent;      /* orthographic: half the side of the square view, world units */
    float fov_y;            /* perspective: full vertical field of view, degrees */
    float eye[3];
    float right[3], up[3], forward[3]; /* orthonormal; forward points from the eye to the origin */
} mx_camera;

/* Orthographic camera at (azimuth, elevation) degrees, radius r, seeing [-half, half]^2. */
void mx_camera_ortho(mx_camera *cam, float azimuth, float elevation, float radius, float half_extent);
/* Perspective camera with a vertical field of view fov_y (degrees). */
void mx_camera_persp(mx_camera *cam, float azimuth, float elevation, float radius, float fov_y);

/* Projects a world point into a w x h image: out = (x, y, depth) in pixels / world units.
 * Returns 0 when the point is behind the eye (perspective only). */
int mx_camera_project(const mx_camera *cam, const float p[3], int w, int h, float out[3]);
/* World-space point seen at continuous pixel position (x, y) with the given depth. */
void mx_camera_unproject(const mx_camera *cam, float x, float y, float depth, int w, int h,
                         float out[3]);
/* Unit vector from a world point towards the eye (for orthographic: -forward). */
void mx_camera_view_dir(const mx_camera *cam, const float p[3], float out[3]);

/* n cameras with positions on a Fibonacci lattice of the sphere (the same template camera
 * for every one: projection, radius, extent or fov copied from `tmpl`). */
void mx_camera_fibonacci(mx_camera *out, int n, const mx_camera *tmpl);

/* View word for prompts by pose: "front", "back", "side", "top" or "bottom". */
const char *mx_camera_view_word(const mx_camera *cam);

/* Square crop of a render (pixel box) around the object, with a relative margin. */
typedef struct mx_crop {
    int x0, y0, size;
} mx_crop;

/* Square box around the foreground (mask != 0) of a w x h image, grown by margin (0.05 =
 * 5% per side) and clamped to stay inside the image when it fits; the whole image when
 * the mask is empty. */
mx_crop mx_crop_from_mask(const unsigned char *mask, int w, int h, float margin);
/* dst (allocated here, size x size, src->c channels) = the crop of src resampled by area
 * averaging / bilinear filtering; rows in bands on pool (NULL: serial), the same result on any pool. */
int mx_crop_resize(const mx_image *src, mx_crop crop, int size, mx_pool *pool, mx_image *dst, mx_status *st);
/* Inverse: writes src (the model image) back into the crop box of dst (full render size),
 * bilinear; pixels of dst outside the box are left as they are. Rows on pool as mx_crop_resize. */
void mx_crop_paste(const mx_image *src, mx_crop crop, mx_pool *pool, mx_image *dst);

#endif
