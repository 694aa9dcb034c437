/* Control images for the ControlNets and the moves between the renders (HWC images at the
 * render size) and the model's planar batches (NCHW at the model image size). */
#ifndef MX_CONDITION_H
#define MX_CONDITION_H

#include <stdint.h>

#include "../geom/image.h"
#include "../geom/raster.h"

/* Depth control of ControlNet depth v1.1 (in [0, 1], near = bright): over the visible pixels,
 * value = 0.2 + 0.8 (d_far - d) / (d_far - d_near); background 0. One channel: the network's three
 * are this one repeated (mx_job_view_controls copies it into each after the resize, which then
 * samples one channel instead of three equal ones). */
int mx_depth_image(const mx_gbuffer *gb, mx_image *out, mx_status *st);
/* A uint8 mask as a 1-channel float image (1 where set). */
int mx_mask_image(const uint8_t *mask, int w, int h, mx_image *out, mx_status *st);
/* Inpainting control (ControlNet inpaint v1.1): rgb where mask < 0.5, -1 where mask >= 0.5
 * (the pixels to paint). rgb (3+ channels) and mask (1 channel) have the same size. */
int mx_inpaint_image(const mx_image *rgb, const mx_image *mask, mx_image *out, mx_status *st);

/* The paint mask the inpaint pipeline gets: the pipeline keeps or repaints whole latent cells
 * (cell x cell pixels, its nearest resize reads one pixel per cell), so a cell is painted
 * (1 in all its pixels) when any pixel of it, or of the cells within `dilate` cells, has
 * mask > 0: no untextured pixel is kept from the current render, whose unknown texels are
 * only a stand-in colour. mask: 1 channel; out: 1 channel, same size. */
int mx_paint_mask_cells(const mx_image *mask, int cell, int dilate, mx_image *out, mx_status *st);

/* Writes the channels of img (HWC) into planes [c][plane_h][plane_w] at column x0
 * (plane_h = img->h; the image must fit). */
void mx_image_to_planes(const mx_image *img, float *planes, int plane_w, int x0);
/* out (allocated, HWC, c channels) = the w columns from x0 of planes [c][h][plane_w]. */
int mx_planes_to_image(const float *planes, int c, int h, int plane_w, int x0, int w, mx_image *out,
                       mx_status *st);

#endif
