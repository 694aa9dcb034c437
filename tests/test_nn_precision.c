/* The bf16 precision policy (pipeline/nn/precision.h): which convolutions and networks run in
 * fp32 under a bf16 context, by parameter path; and mx_ctx_fp32, the context they run on. */
#include <stdio.h>

#include "../ops/ops.h"
#include "../pipeline/nn/precision.h"
#include "util_test.h"

static void check_conv(const char *path, int want_fp32) {
    int got = mx_prec_conv_fp32(path);
    printf("%-52s %s%s\n", path, got ? "fp32" : "bf16", got == want_fp32 ? "" : "  WRONG");
    CHECK(got == want_fp32);
}

static void test_conv_rule(void) {
    /* fp32: fed by unnormalised activations */
    check_conv("conv_in", 1);
    check_conv("controlnet_cond_embedding.conv_in", 1);
    check_conv("controlnet_cond_embedding.blocks.3", 1);
    check_conv("controlnet_cond_embedding.conv_out", 1);
    check_conv("controlnet_down_blocks.11", 1);
    check_conv("controlnet_mid_block", 1);
    check_conv("down_blocks.1.resnets.0.conv_shortcut", 1);
    check_conv("down_blocks.0.downsamplers.0.conv", 1);
    check_conv("down_blocks.2.attentions.1.proj_in", 1);
    check_conv("mid_block.attentions.0.proj_out", 1);
    /* bf16: fed by a GroupNorm */
    check_conv("down_blocks.0.resnets.1.conv1", 0);
    check_conv("mid_block.resnets.1.conv2", 0);
    check_conv("conv_out", 0);
    /* bf16 by measurement: the upsamplers */
    check_conv("up_blocks.2.upsamplers.0.conv", 0);
    /* names that only look alike */
    check_conv("conv_input", 0);
    check_conv("up_blocks.1.my_downsamplers.0.conv", 0);
    check_conv("encoder.layers.3.conv.0", 0); /* TAESD: follows the context */
    CHECK(mx_prec_net_fp32(MX_NET_VAE) == 1);
    /* ...but for the 3×3 convolutions of its decoder's two full-resolution up blocks */
    CHECK(mx_prec_vae_up_block_bf16(3, 4) && mx_prec_vae_up_block_bf16(2, 4));
    CHECK(!mx_prec_vae_up_block_bf16(1, 4) && !mx_prec_vae_up_block_bf16(0, 4));
    CHECK(mx_prec_vae_up_block_bf16(1, 3) && !mx_prec_vae_up_block_bf16(0, 3));
    CHECK(mx_prec_net_fp32(MX_NET_UNET) == 0 && mx_prec_net_fp32(MX_NET_TAESD) == 0 && mx_prec_net_fp32(MX_NET_TEXT_ENCODER) == 0);
}

/* mx_ctx_fp32: a bf16 table becomes the fp32 one below it; fp32 tables and NULL stay. */
static void test_ctx_fp32(void) {
    for (mx_isa isa = MX_ISA_SCALAR; isa < MX_ISA_COUNT; isa++) {
        mx_ctx c = {.k = mx_kernels_for(isa)};
        mx_ctx f = mx_ctx_fp32(&c);
        mx_isa want = mx_isa_fp32_level(c.k->isa);
        printf("mx_ctx_fp32(%s) = %s\n", mx_isa_name(c.k->isa), mx_isa_name(f.k->isa));
        CHECK(f.k->isa == want && mx_isa_precision(f.k->isa) == MX_PREC_FP32);
        CHECK(f.pool == c.pool && f.be == c.be && f.scratch == c.scratch && f.measuring == c.measuring);
    }
    mx_ctx none = mx_ctx_fp32(NULL);
    CHECK(none.k == NULL && none.be == NULL);
}

int main(void) {
    test_conv_rule();
    test_ctx_fp32();
    return mx_test_finish("test_nn_precision");
}
