/* SPDX-License-Identifier: MIT */
/* Compiled once per public header: each must compile alone. */
#include VAFM_TEST_HEADER

int main(void)
{
    return 0;
}
