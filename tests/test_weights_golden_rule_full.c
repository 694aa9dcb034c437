/* The complete golden-v1 check (every tensor of the four SD1.5 networks, ~1.4 G values):
 * runs when MATEX_FULL=1 (make test-full); the same source as test_weights_golden_rule. */
#define GOLDEN_FULL 1
#include "test_weights_golden_rule.c"
