/* SPDX-License-Identifier: MIT */
/*
 * Philox4x32-10 counter-based streams and the 256-level ziggurat normal (design: rng_philox.h).
 * The public functions of vafm/rng.h are thin wrappers over the static inline versions.
 */
#include "rng_philox.h"

#include <math.h>
#include <stdint.h>

#include "vafm/rng.h"

/* Ziggurat constants: r = X[1] = 3.6541528853610087716 (start of the tail), 1/r. Common area of the
 * 256 layers v = 4.9286732339746553474e-3 (unnormalised f(x) = exp(-x^2/2)). */
#define ZIG_R 0x1.d3bb48209ad33p+1
#define ZIG_INV_R 0x1.183aa6c20e8c1p-2

/*
 * Tables, generated offline (mpmath, 80 digits): r solved so that the recursion
 *   X[0] = v / f(r), X[1] = r, X[i+1] = f^-1(f(X[i]) + v / X[i]), X[256] = 0
 * closes the top layer exactly (residual < 1e-60); then
 *   K[i] = ceil(2^53 X[i+1] / X[i]),  W[i] = X[i] 2^-53 (rounded to nearest),  F[i] = f(X[i]) (rounded).
 * A draw in layer i with j = u >> 11 < K[i] lies inside the layer below's width: accept x = j W[i].
 */
VAFM_RNG_HIDDEN const uint64_t vafm_zig_k[256] = {
    UINT64_C(0x1de67b004bdecb), UINT64_C(0x1e34b496663894), UINT64_C(0x1ecd8befe06059),
    UINT64_C(0x1f13f491483bf8), UINT64_C(0x1f3d2e3c028b2f), UINT64_C(0x1f5880b05450e8),
    UINT64_C(0x1f6c0d8800a868), UINT64_C(0x1f7acb03817074), UINT64_C(0x1f86565e3c45da),
    UINT64_C(0x1f8fa4dd9a5a46), UINT64_C(0x1f9751b0bc2364), UINT64_C(0x1f9dc408ec3f3e),
    UINT64_C(0x1fa3434f698f59), UINT64_C(0x1fa80293c5e024), UINT64_C(0x1fac275b7aca17),
    UINT64_C(0x1fafcdde919e09), UINT64_C(0x1fb30bc36574eb), UINT64_C(0x1fb5f1f05c0506),
    UINT64_C(0x1fb88dca537e26), UINT64_C(0x1fbaea138c77fb), UINT64_C(0x1fbd0f8afdfd55),
    UINT64_C(0x1fbf056056e355), UINT64_C(0x1fc0d189dccf5f), UINT64_C(0x1fc27904f10629),
    UINT64_C(0x1fc4000732aaaf), UINT64_C(0x1fc56a245fc9fb), UINT64_C(0x1fc6ba6bdd6338),
    UINT64_C(0x1fc7f37ffa3c6f), UINT64_C(0x1fc917a86de8b0), UINT64_C(0x1fca28e12ee501),
    UINT64_C(0x1fcb28e671ee85), UINT64_C(0x1fcc193e7060fc), UINT64_C(0x1fccfb416d57b2),
    UINT64_C(0x1fcdd020554404), UINT64_C(0x1fce98ea3ed54b), UINT64_C(0x1fcf569104677f),
    UINT64_C(0x1fd009ed215280), UINT64_C(0x1fd0b3c0f563d5), UINT64_C(0x1fd154bb89d1cd),
    UINT64_C(0x1fd1ed7aed8bad), UINT64_C(0x1fd27e8e3a8e52), UINT64_C(0x1fd30877528f47),
    UINT64_C(0x1fd38bac5eac75), UINT64_C(0x1fd408991bb3ee), UINT64_C(0x1fd47f9ffae7cb),
    UINT64_C(0x1fd4f11b1dc64e), UINT64_C(0x1fd55d5d3244ae), UINT64_C(0x1fd5c4b23405d2),
    UINT64_C(0x1fd62760165a97), UINT64_C(0x1fd685a75a3f3d), UINT64_C(0x1fd6dfc3930a86),
    UINT64_C(0x1fd735ebdc19b9), UINT64_C(0x1fd78853416d23), UINT64_C(0x1fd7d7291cdfa2),
    UINT64_C(0x1fd8229969666a), UINT64_C(0x1fd86acd0d92c4), UINT64_C(0x1fd8afea1e63fc),
    UINT64_C(0x1fd8f2141b52f1), UINT64_C(0x1fd9316c246182), UINT64_C(0x1fd96e112add69),
    UINT64_C(0x1fd9a8201d6f71), UINT64_C(0x1fd9dfb40ffc67), UINT64_C(0x1fda14e65fcc88),
    UINT64_C(0x1fda47ced45faf), UINT64_C(0x1fda7883bd4845), UINT64_C(0x1fdaa71a0d5bff),
    UINT64_C(0x1fdad3a5738056), UINT64_C(0x1fdafe3871506d), UINT64_C(0x1fdb26e46fd31a),
    UINT64_C(0x1fdb4db9d27193), UINT64_C(0x1fdb72c80859e8), UINT64_C(0x1fdb961d9c73a7),
    UINT64_C(0x1fdbb7c84408fb), UINT64_C(0x1fdbd7d4ec42d9), UINT64_C(0x1fdbf64fc69398),
    UINT64_C(0x1fdc134454288f), UINT64_C(0x1fdc2ebd7078b4), UINT64_C(0x1fdc48c55b040a),
    UINT64_C(0x1fdc6165c055af), UINT64_C(0x1fdc78a7c2589f), UINT64_C(0x1fdc8e94000d9e),
    UINT64_C(0x1fdca3329caf6c), UINT64_C(0x1fdcb68b465112), UINT64_C(0x1fdcc8a53c00ff),
    UINT64_C(0x1fdcd987537abd), UINT64_C(0x1fdce937fe6fff), UINT64_C(0x1fdcf7bd4f7110),
    UINT64_C(0x1fdd051cfe7bfa), UINT64_C(0x1fdd115c6d38f4), UINT64_C(0x1fdd1c80aaea2b),
    UINT64_C(0x1fdd268e781473), UINT64_C(0x1fdd2f8a49e5c8), UINT64_C(0x1fdd37784d5e5e),
    UINT64_C(0x1fdd3e5c6a4049), UINT64_C(0x1fdd443a45c9b4), UINT64_C(0x1fdd4915453d06),
    UINT64_C(0x1fdd4cf0903a49), UINT64_C(0x1fdd4fcf12eca8), UINT64_C(0x1fdd51b3800ebc),
    UINT64_C(0x1fdd52a052c81f), UINT64_C(0x1fdd5297d06678), UINT64_C(0x1fdd519c09f415),
    UINT64_C(0x1fdd4faeddadf4), UINT64_C(0x1fdd4cd1f85ae3), UINT64_C(0x1fdd4906d68557),
    UINT64_C(0x1fdd444ec5995d), UINT64_C(0x1fdd3eaae4e7e8), UINT64_C(0x1fdd381c2690b7),
    UINT64_C(0x1fdd30a35053d7), UINT64_C(0x1fdd2840fc4bb5), UINT64_C(0x1fdd1ef59990a4),
    UINT64_C(0x1fdd14c16cc686), UINT64_C(0x1fdd09a4909566), UINT64_C(0x1fdcfd9ef60d74),
    UINT64_C(0x1fdcf0b064f703), UINT64_C(0x1fdce2d87c0ef5), UINT64_C(0x1fdcd416b12fe2),
    UINT64_C(0x1fdcc46a51685c), UINT64_C(0x1fdcb3d280fe83), UINT64_C(0x1fdca24e3b610d),
    UINT64_C(0x1fdc8fdc5305e8), UINT64_C(0x1fdc7c7b71367a), UINT64_C(0x1fdc682a15c978),
    UINT64_C(0x1fdc52e696ca49), UINT64_C(0x1fdc3caf200dc0), UINT64_C(0x1fdc2581b2b40d),
    UINT64_C(0x1fdc0d5c24978a), UINT64_C(0x1fdbf43c1fa828), UINT64_C(0x1fdbda1f213300),
    UINT64_C(0x1fdbbf027915a5), UINT64_C(0x1fdba2e348dca5), UINT64_C(0x1fdb85be82cca5),
    UINT64_C(0x1fdb6790e8d567), UINT64_C(0x1fdb48570b6e09), UINT64_C(0x1fdb280d485992),
    UINT64_C(0x1fdb06afc95304), UINT64_C(0x1fdae43a829fd1), UINT64_C(0x1fdac0a93187ba),
    UINT64_C(0x1fda9bf75ab0dc), UINT64_C(0x1fda7620485e99), UINT64_C(0x1fda4f1f089207),
    UINT64_C(0x1fda26ee6b0a51), UINT64_C(0x1fd9fd88ff236f), UINT64_C(0x1fd9d2e9119168),
    UINT64_C(0x1fd9a708a9f62b), UINT64_C(0x1fd979e1884ffd), UINT64_C(0x1fd94b6d223e22),
    UINT64_C(0x1fd91ba4a01969), UINT64_C(0x1fd8ea80d9dde9), UINT64_C(0x1fd8b7fa53e32d),
    UINT64_C(0x1fd884093b5fa7), UINT64_C(0x1fd84ea562b42a), UINT64_C(0x1fd817c63d7bd1),
    UINT64_C(0x1fd7df62dc5c7c), UINT64_C(0x1fd7a571e893a0), UINT64_C(0x1fd769e99f3af9),
    UINT64_C(0x1fd72cbfcc4027), UINT64_C(0x1fd6ede9c509f4), UINT64_C(0x1fd6ad5c62c569),
    UINT64_C(0x1fd66b0bfc5496), UINT64_C(0x1fd626ec5fd825), UINT64_C(0x1fd5e0f0cbcc79),
    UINT64_C(0x1fd5990be7b240), UINT64_C(0x1fd54f2fbc39df), UINT64_C(0x1fd5034daae834),
    UINT64_C(0x1fd4b556652a5a), UINT64_C(0x1fd46539e2cd49), UINT64_C(0x1fd412e757ccf8),
    UINT64_C(0x1fd3be4d296dab), UINT64_C(0x1fd36758e290cc), UINT64_C(0x1fd30df7273544),
    UINT64_C(0x1fd2b213a711d6), UINT64_C(0x1fd253990f363a), UINT64_C(0x1fd1f270fa9ded),
    UINT64_C(0x1fd18e83e19d79), UINT64_C(0x1fd127b90810c9), UINT64_C(0x1fd0bdf66a2e77),
    UINT64_C(0x1fd05120a7e119), UINT64_C(0x1fcfe11aee8486), UINT64_C(0x1fcf6dc6e0e144),
    UINT64_C(0x1fcef7047d3c73), UINT64_C(0x1fce7cb2014e03), UINT64_C(0x1fcdfeabcbe9e5),
    UINT64_C(0x1fcd7ccc3c2356), UINT64_C(0x1fccf6eb8daaf1), UINT64_C(0x1fcc6cdfb220f0),
    UINT64_C(0x1fcbde7c270d13), UINT64_C(0x1fcb4b91c82425), UINT64_C(0x1fcab3ee9d78ef),
    UINT64_C(0x1fca175da52a4a), UINT64_C(0x1fc975a69812b8), UINT64_C(0x1fc8ce8da8ee6a),
    UINT64_C(0x1fc821d33d5afe), UINT64_C(0x1fc76f33a00056), UINT64_C(0x1fc6b666ab1a96),
    UINT64_C(0x1fc5f71f6a830d), UINT64_C(0x1fc5310bb43724), UINT64_C(0x1fc463d3b63953),
    UINT64_C(0x1fc38f19787f32), UINT64_C(0x1fc2b278517098), UINT64_C(0x1fc1cd844b44b1),
    UINT64_C(0x1fc0dfc97849e4), UINT64_C(0x1fbfe8cb33da7e), UINT64_C(0x1fbee8034d685d),
    UINT64_C(0x1fbddce11aa29d), UINT64_C(0x1fbcc6c86d3ec8), UINT64_C(0x1fbba510685f20),
    UINT64_C(0x1fba770230e53b), UINT64_C(0x1fb93bd77334fb), UINT64_C(0x1fb7f2b8b7f9a2),
    UINT64_C(0x1fb69abb805c40), UINT64_C(0x1fb532e020bd18), UINT64_C(0x1fb3ba0f4f5ba6),
    UINT64_C(0x1fb22f175a5918), UINT64_C(0x1fb090a8f611d1), UINT64_C(0x1faedd5391d065),
    UINT64_C(0x1fad13811d33d9), UINT64_C(0x1fab3171241ea6), UINT64_C(0x1fa935332168f4),
    UINT64_C(0x1fa71c9fe1923d), UINT64_C(0x1fa4e551c5e8a1), UINT64_C(0x1fa28c9bad89cb),
    UINT64_C(0x1fa00f7e3b9262), UINT64_C(0x1f9d6a9b1fd933), UINT64_C(0x1f9a9a25f07389),
    UINT64_C(0x1f9799d2044635), UINT64_C(0x1f9464bc97bd0b), UINT64_C(0x1f90f552512d4a),
    UINT64_C(0x1f8d452ef5dc61), UINT64_C(0x1f894cf5c4b7a3), UINT64_C(0x1f8504206f4491),
    UINT64_C(0x1f8060c1fed8af), UINT64_C(0x1f7b573a0817dc), UINT64_C(0x1f75d9d343ca1a),
    UINT64_C(0x1f6fd846cdfcf0), UINT64_C(0x1f693f1aa6e98c), UINT64_C(0x1f61f6ce31721d),
    UINT64_C(0x1f59e2c1a6a9b8), UINT64_C(0x1f50dfbcb697f2), UINT64_C(0x1f46c1eb03f4e6),
    UINT64_C(0x1f3b520fb7ea12), UINT64_C(0x1f2e498e9ba1b5), UINT64_C(0x1f1f4caf064bbc),
    UINT64_C(0x1f0de218c6afa6), UINT64_C(0x1ef965d8508937), UINT64_C(0x1ee0f4eaa72d4a),
    UINT64_C(0x1ec34bc837472d), UINT64_C(0x1e9e8d2ac24ab7), UINT64_C(0x1e6fdac3ff962f),
    UINT64_C(0x1e328e15f48958), UINT64_C(0x1dde9702fd9572), UINT64_C(0x1d64abd3a7eefd),
    UINT64_C(0x1ca3ecfd83ddd9), UINT64_C(0x1b46a9f57b028d), UINT64_C(0x18117d31f78d6d),
    UINT64_C(0x00000000000000),
};

VAFM_RNG_HIDDEN const double vafm_zig_w[256] = {
    0x1.f493b7815d982p-52, 0x1.d3bb48209ad33p-52, 0x1.b981f3878fdb0p-52,
    0x1.a8fdc78947759p-52, 0x1.9cbee014057aap-52, 0x1.92ee0946f4496p-52,
    0x1.8ab0fbfaa7c14p-52, 0x1.839030529f233p-52, 0x1.7d42df4d6ce8bp-52,
    0x1.7799556090672p-52, 0x1.72728f05f7a33p-52, 0x1.6db6b8d09e231p-52,
    0x1.69540be9fe5c2p-52, 0x1.653ce7b006aeap-52, 0x1.61669cf861e4bp-52,
    0x1.5dc8a243ad0fep-52, 0x1.5a5c08b718dd9p-52, 0x1.571b1a94ae41cp-52,
    0x1.54011523a7e43p-52, 0x1.5109f53e9ac42p-52, 0x1.4e3250dcd8903p-52,
    0x1.4b7739d6b5a28p-52, 0x1.48d62759c43bdp-52, 0x1.464ce44a73a16p-52,
    0x1.43d9815545e94p-52, 0x1.417a49cb9e5dbp-52, 0x1.3f2dbaa60f475p-52,
    0x1.3cf27b31704a6p-52, 0x1.3ac7570ae88fap-52, 0x1.38ab39256410ap-52,
    0x1.369d27a33a840p-52, 0x1.349c405ae12a3p-52, 0x1.32a7b5e68a4a3p-52,
    0x1.30becd256aeeep-52, 0x1.2ee0db1a978f5p-52, 0x1.2d0d43196db97p-52,
    0x1.2b437532a0a53p-52, 0x1.2982ecd770e78p-52, 0x1.27cb2faa8592ep-52,
    0x1.261bcc77658e0p-52, 0x1.24745a4ac9c24p-52, 0x1.22d477a6fd3efp-52,
    0x1.213bc9d04cc82p-52, 0x1.1fa9fc2e2d901p-52, 0x1.1e1ebfbe4ae39p-52,
    0x1.1c99ca971a695p-52, 0x1.1b1ad777f2f8fp-52, 0x1.19a1a564eebadp-52,
    0x1.182df74d21262p-52, 0x1.16bf93b9deef5p-52, 0x1.1556448602e3dp-52,
    0x1.13f1d69c4096fp-52, 0x1.129219bbb5d37p-52, 0x1.1136e04207043p-52,
    0x1.0fdffefa69fb8p-52, 0x1.0e8d4cf116594p-52, 0x1.0d3ea34aa3d32p-52,
    0x1.0bf3dd1eed449p-52, 0x1.0aacd7571c0c5p-52, 0x1.0969708e8a255p-52,
    0x1.082988f632e18p-52, 0x1.06ed023a72669p-52, 0x1.05b3bf6adb37ep-52,
    0x1.047da4e3ef5c7p-52, 0x1.034a983a902abp-52, 0x1.021a8028fc947p-52,
    0x1.00ed447d3a075p-52, 0x1.ff859c118f60bp-53, 0x1.fd360d22fe785p-53,
    0x1.faebb187122bfp-53, 0x1.f8a6604899782p-53, 0x1.f665f20c90168p-53,
    0x1.f42a40fb74d6dp-53, 0x1.f1f328ac25321p-53, 0x1.efc086101eca9p-53,
    0x1.ed9237610a73ap-53, 0x1.eb681c0f76f08p-53, 0x1.e94214b2abf09p-53,
    0x1.e72002f97fe23p-53, 0x1.e501c99c1d186p-53, 0x1.e2e74c4ea46f3p-53,
    0x1.e0d06fb49d219p-53, 0x1.debd195522e34p-53, 0x1.dcad2f8fc490cp-53,
    0x1.daa0999206e6ep-53, 0x1.d8973f4d7fba4p-53, 0x1.d691096e7f123p-53,
    0x1.d48de1533c647p-53, 0x1.d28db1037ef20p-53, 0x1.d0906328b8f6ep-53,
    0x1.ce95e3068e037p-53, 0x1.cc9e1c73bd690p-53, 0x1.caa8fbd36a2abp-53,
    0x1.c8b66e0eba617p-53, 0x1.c6c6608ec8705p-53, 0x1.c4d8c136e0d1dp-53,
    0x1.c2ed7e5f07a2dp-53, 0x1.c10486cec16a0p-53, 0x1.bf1dc9b81ae82p-53,
    0x1.bd3936b2ec0a2p-53, 0x1.bb56bdb85256ep-53, 0x1.b9764f1e5f73dp-53,
    0x1.b797db93f8928p-53, 0x1.b5bb541ce3d04p-53, 0x1.b3e0aa0e00c01p-53,
    0x1.b207cf09a985cp-53, 0x1.b030b4fc3a11bp-53, 0x1.ae5b4e18bb338p-53,
    0x1.ac878cd5af5cfp-53, 0x1.aab563e9ff10ap-53, 0x1.a8e4c64a0313fp-53,
    0x1.a715a724aa9a7p-53, 0x1.a547f9e0bbb8bp-53, 0x1.a37bb21a2c85ep-53,
    0x1.a1b0c39f93696p-53, 0x1.9fe7226fad24dp-53, 0x1.9e1ec2b6f7414p-53,
    0x1.9c5798cd5d92ep-53, 0x1.9a919933f99c1p-53, 0x1.98ccb892e2a33p-53,
    0x1.9708ebb70d5efp-53, 0x1.954627903a28bp-53, 0x1.9384612ef0afep-53,
    0x1.91c38dc288349p-53, 0x1.9003a2973b591p-53, 0x1.8e44951446a28p-53,
    0x1.8c865aba10c9dp-53, 0x1.8ac8e9205c044p-53, 0x1.890c35f47f72ep-53,
    0x1.875036f7a7ec7p-53, 0x1.8594e1fd1f5bep-53, 0x1.83da2ce899f16p-53,
    0x1.82200dac88677p-53, 0x1.80667a486ea1fp-53, 0x1.7ead68c73dee7p-53,
    0x1.7cf4cf3db22fcp-53, 0x1.7b3ca3c8b140ap-53, 0x1.7984dc8babd94p-53,
    0x1.77cd6faeff44ap-53, 0x1.7616535e57320p-53, 0x1.745f7dc70eeddp-53,
    0x1.72a8e516914c7p-53, 0x1.70f27f78b68ecp-53, 0x1.6f3c43161f856p-53,
    0x1.6d8626128d354p-53, 0x1.6bd01e8b343bdp-53, 0x1.6a1a22950b2b3p-53,
    0x1.6864283b13139p-53, 0x1.66ae257c99674p-53, 0x1.64f8104b7260dp-53,
    0x1.6341de8a2b0a4p-53, 0x1.618b860a31fc5p-53, 0x1.5fd4fc89f5e39p-53,
    0x1.5e1e37b2f8cd4p-53, 0x1.5c672d17d733fp-53, 0x1.5aafd23241b5ap-53,
    0x1.58f81c60e8515p-53, 0x1.574000e555f79p-53, 0x1.558774e1bb2c9p-53,
    0x1.53ce6d56a6650p-53, 0x1.5214df20a8b5cp-53, 0x1.505abef5e5563p-53,
    0x1.4ea001638a606p-53, 0x1.4ce49acb311ddp-53, 0x1.4b287f602415ep-53,
    0x1.496ba32488f30p-53, 0x1.47adf9e66c338p-53, 0x1.45ef773cac75ep-53,
    0x1.44300e83c30a6p-53, 0x1.426fb2da6745fp-53, 0x1.40ae571e09e76p-53,
    0x1.3eebede725a85p-53, 0x1.3d28698561de3p-53, 0x1.3b63bbfb83d06p-53,
    0x1.399dd6fb2b267p-53, 0x1.37d6abe05586cp-53, 0x1.360e2baca52d7p-53,
    0x1.3444470265ea4p-53, 0x1.3278ee1f4b933p-53, 0x1.30ac10d6e48dap-53,
    0x1.2edd9e8cba990p-53, 0x1.2d0d862e1b855p-53, 0x1.2b3bb62b82edbp-53,
    0x1.29681c719d71dp-53, 0x1.2792a661dd381p-53, 0x1.25bb40ca96bfep-53,
    0x1.23e1d7de9c322p-53, 0x1.2206572c4c6ecp-53, 0x1.2028a9940a0a3p-53,
    0x1.1e48b93e0d431p-53, 0x1.1c666f8f82acfp-53, 0x1.1a81b51ee6d8bp-53,
    0x1.189a71a78da37p-53, 0x1.16b08bfc42020p-53, 0x1.14c3e9f8e9143p-53,
    0x1.12d4707310fc1p-53, 0x1.10e20329515f1p-53, 0x1.0eec84b16086fp-53,
    0x1.0cf3d664bcc83p-53, 0x1.0af7d84bc6116p-53, 0x1.08f869071f40fp-53,
    0x1.06f565b72a014p-53, 0x1.04eea9e16a5ffp-53, 0x1.02e40f5398f9dp-53,
    0x1.00d56e04234eep-53, 0x1.fd8537dfa2eb1p-54, 0x1.f956d9e87d7b2p-54,
    0x1.f51f654d8f68cp-54, 0x1.f0de784f0622ap-54, 0x1.ec93abdf982d2p-54,
    0x1.e83e9337a6f04p-54, 0x1.e3debb5d2ee02p-54, 0x1.df73aa9f17656p-54,
    0x1.dafce0023b8c8p-54, 0x1.d679d29e41f14p-54, 0x1.d1e9f0e80b74bp-54,
    0x1.cd4c9fe72268fp-54, 0x1.c8a13a5323b66p-54, 0x1.c3e70f9594ef8p-54,
    0x1.bf1d62abf8239p-54, 0x1.ba4368e529f40p-54, 0x1.b558487427a2fp-54,
    0x1.b05b16d136ca2p-54, 0x1.ab4ad6e101636p-54, 0x1.a62676d77cd5fp-54,
    0x1.a0eccdca4a731p-54, 0x1.9b9c98e38c54dp-54, 0x1.96347822c1ef0p-54,
    0x1.90b2ea94ecf9ep-54, 0x1.8b1649e7b769fp-54, 0x1.855cc53430a7dp-54,
    0x1.7f845ad46f549p-54, 0x1.798ad10b32a7ep-54, 0x1.736dad346f8adp-54,
    0x1.6d2a292000576p-54, 0x1.66bd261a37c44p-54, 0x1.60231cfd97ef1p-54,
    0x1.59580a707ce9cp-54, 0x1.52575621ad379p-54, 0x1.4b1bb363dfeadp-54,
    0x1.439ef8dff9b5ap-54, 0x1.3bd9ec1a2b134p-54, 0x1.33c3fc05791fap-54,
    0x1.2b52e3863d885p-54, 0x1.227a28f7a1afap-54, 0x1.192a69741367dp-54,
    0x1.0f5053b025d4ap-54, 0x1.04d32278ebbb4p-54, 0x1.f32482d4cd5d0p-55,
    0x1.dac2f5a747281p-55, 0x1.c004d2f386207p-55, 0x1.a230c2e4cd0cbp-55,
    0x1.801fce82fa71ap-55, 0x1.57cb938443b71p-55, 0x1.250af3c2c5bc6p-55,
    0x1.b8d0be3fdf702p-56,
};

VAFM_RNG_HIDDEN const double vafm_zig_f[257] = {
    0x1.f4a946f13842fp-12, 0x1.4a605b6b9f70dp-10, 0x1.55f9f43c1b070p-9,
    0x1.08a1f03b0b205p-8, 0x1.69ea8d90cb864p-8, 0x1.ce160f8ec683cp-8,
    0x1.1a59229952f95p-7, 0x1.4eb96421acfe7p-7, 0x1.841040d8da47ep-7,
    0x1.ba48d274f8fb3p-7, 0x1.f152a4f72dd53p-7, 0x1.149033460301ap-6,
    0x1.30d388dab5e1ap-6, 0x1.4d6eaf2fbb067p-6, 0x1.6a5daf40bbf87p-6,
    0x1.879d1b600c10bp-6, 0x1.a529f4e22ebf4p-6, 0x1.c301983cd0912p-6,
    0x1.e121adb828c69p-6, 0x1.ff881d718a5b5p-6, 0x1.0f1982e968009p-5,
    0x1.1e9059f1f6ab6p-5, 0x1.2e27ce83df495p-5, 0x1.3ddf2ce98eec7p-5,
    0x1.4db5d0e11275cp-5, 0x1.5dab23cf2add1p-5, 0x1.6dbe9b398d062p-5,
    0x1.7defb77af271cp-5, 0x1.8e3e02a68b5a9p-5, 0x1.9ea90f9295561p-5,
    0x1.af30790385f6fp-5, 0x1.bfd3e0f282a2cp-5, 0x1.d092efeadf162p-5,
    0x1.e16d547b25185p-5, 0x1.f262c2b6c6e33p-5, 0x1.01b979e30e496p-4,
    0x1.0a4ed2c159622p-4, 0x1.12f14d0f2179dp-4, 0x1.1ba0cbe97897ep-4,
    0x1.245d344dd0d8fp-4, 0x1.2d266cf9b310dp-4, 0x1.35fc5e4d93e69p-4,
    0x1.3edef23269a81p-4, 0x1.47ce1401b2212p-4, 0x1.50c9b06fa2babp-4,
    0x1.59d1b5774669dp-4, 0x1.62e6124854d10p-4, 0x1.6c06b73694a46p-4,
    0x1.753395aaa116dp-4, 0x1.7e6ca013eefccp-4, 0x1.87b1c9dbf2846p-4,
    0x1.9103075a4a09fp-4, 0x1.9a604dc9d5b0bp-4, 0x1.a3c9933ea627bp-4,
    0x1.ad3ece9caf627p-4, 0x1.b6bff78f2e228p-4, 0x1.c04d0680b100ap-4,
    0x1.c9e5f493b7404p-4, 0x1.d38abb9bd91dcp-4, 0x1.dd3b56176e88bp-4,
    0x1.e6f7bf29aa546p-4, 0x1.f0bff29520e16p-4, 0x1.fa93ecb6b222bp-4,
    0x1.0239d54067d29p-3, 0x1.072f94bb8bf84p-3, 0x1.0c2b33d5209b9p-3,
    0x1.112cb1da26eb8p-3, 0x1.16340e5a82d62p-3, 0x1.1b41492757d42p-3,
    0x1.2054625183c34p-3, 0x1.256d5a2835eb6p-3, 0x1.2a8c3137a071bp-3,
    0x1.2fb0e847c2a65p-3, 0x1.34db805b4ab89p-3, 0x1.3a0bfaae8d7eep-3,
    0x1.3f4258b6931afp-3, 0x1.447e9c20375d6p-3, 0x1.49c0c6cf5ce30p-3,
    0x1.4f08dade31fc6p-3, 0x1.5456da9c8683bp-3, 0x1.59aac88f31d74p-3,
    0x1.5f04a76f88400p-3, 0x1.64647a2adf1a4p-3, 0x1.69ca43e21f261p-3,
    0x1.6f3607e964719p-3, 0x1.74a7c9c7ab5a8p-3, 0x1.7a1f8d368a323p-3,
    0x1.7f9d5621f7174p-3, 0x1.852128a819a38p-3, 0x1.8aab09192815ap-3,
    0x1.903afbf74fa68p-3, 0x1.95d105f6a7c27p-3, 0x1.9b6d2bfd2fe5ap-3,
    0x1.a10f7322d7e3cp-3, 0x1.a6b7e0b19267cp-3, 0x1.ac667a2571805p-3,
    0x1.b21b452ccd13ap-3, 0x1.b7d647a8731abp-3, 0x1.bd9787abe18a2p-3,
    0x1.c35f0b7d89d46p-3, 0x1.c92cd9971df52p-3, 0x1.cf00f8a5e6fcap-3,
    0x1.d4db6f8b2514cp-3, 0x1.dabc455c79006p-3, 0x1.e0a3816457181p-3,
    0x1.e6912b2283cd9p-3, 0x1.ec854a4c99c3ep-3, 0x1.f27fe6ce998ccp-3,
    0x1.f88108cb8322fp-3, 0x1.fe88b89df93bcp-3, 0x1.024b7f6c7747ap-2,
    0x1.0555f2242e9d4p-2, 0x1.0863b8f904331p-2, 0x1.0b74d88b242d4p-2,
    0x1.0e895598709bdp-2, 0x1.11a134fcf241dp-2, 0x1.14bc7bb34ee63p-2,
    0x1.17db2ed5454e5p-2, 0x1.1afd539c2f04cp-2, 0x1.1e22ef6188113p-2,
    0x1.214c079f7cc9cp-2, 0x1.2478a1f17de86p-2, 0x1.27a8c414db11bp-2,
    0x1.2adc73e963fdap-2, 0x1.2e13b77210764p-2, 0x1.314e94d5af62dp-2,
    0x1.348d125f9d19cp-2, 0x1.37cf368081376p-2, 0x1.3b1507cf143acp-2,
    0x1.3e5e8d08ed2d8p-2, 0x1.41abcd1357a18p-2, 0x1.44fccefc324fcp-2,
    0x1.485199fad6ad4p-2, 0x1.4baa357109ca2p-2, 0x1.4f06a8ebf6d91p-2,
    0x1.5266fc2533beap-2, 0x1.55cb3703d00fdp-2, 0x1.5933619d6eebcp-2,
    0x1.5c9f84376c241p-2, 0x1.600fa7480d2c6p-2, 0x1.6383d377be513p-2,
    0x1.66fc11a25cbdfp-2, 0x1.6a786ad88de1ep-2, 0x1.6df8e86124ca6p-2,
    0x1.717d93ba96148p-2, 0x1.7506769c7b1e8p-2, 0x1.78939af9252e6p-2,
    0x1.7c250aff414acp-2, 0x1.7fbad11b8d90dp-2, 0x1.8354f7faa0dd5p-2,
    0x1.86f38a8ac5ab2p-2, 0x1.8a9693fde9185p-2, 0x1.8e3e1fcb9f113p-2,
    0x1.91ea39b33cb13p-2, 0x1.959aedbe09f8fp-2, 0x1.995048418c0c3p-2,
    0x1.9d0a55e1e93dcp-2, 0x1.a0c923946843bp-2, 0x1.a48cbea20c04bp-2,
    0x1.a85534aa4d87dp-2, 0x1.ac2293a5f5a9ap-2, 0x1.aff4e9ea18550p-2,
    0x1.b3cc462b331c8p-2, 0x1.b7a8b78071319p-2, 0x1.bb8a4d6716d8fp-2,
    0x1.bf7117c616a14p-2, 0x1.c35d26f1d2cb5p-2, 0x1.c74e8bb00d7c3p-2,
    0x1.cb45573c0a843p-2, 0x1.cf419b4ae5b69p-2, 0x1.d3436a102107bp-2,
    0x1.d74ad6426de2dp-2, 0x1.db57f320b56abp-2, 0x1.df6ad47763a03p-2,
    0x1.e3838ea5f9b7ep-2, 0x1.e7a236a4ec3bfp-2, 0x1.ebc6e20bd1f4fp-2,
    0x1.eff1a717e8f8ep-2, 0x1.f4229cb2f7aecp-2, 0x1.f859da7a900c4p-2,
    0x1.fc9778c7bbd9bp-2, 0x1.006dc85b8cac2p-1, 0x1.02931e18b8228p-1,
    0x1.04bbcafa63f2bp-1, 0x1.06e7dccf03c33p-1, 0x1.091761d995d7dp-1,
    0x1.0b4a68d70d9abp-1, 0x1.0d8101041429cp-1, 0x1.0fbb3a232590fp-1,
    0x1.11f9248311f34p-1, 0x1.143ad105ea998p-1, 0x1.16805128639d6p-1,
    0x1.18c9b709b3c4dp-1, 0x1.1b171573fd10ep-1, 0x1.1d687fe549966p-1,
    0x1.1fbe0a992961dp-1, 0x1.2217ca92ff7eep-1, 0x1.2475d5a90db80p-1,
    0x1.26d84290504e9p-1, 0x1.293f28e93cd11p-1, 0x1.2baaa14d79545p-1,
    0x1.2e1ac55ea3beap-1, 0x1.308fafd6438ebp-1, 0x1.33097c9703a32p-1,
    0x1.358848bf550e6p-1, 0x1.380c32bda00d2p-1, 0x1.3a955a662cd0bp-1,
    0x1.3d23e10af31a1p-1, 0x1.3fb7e99585b7fp-1, 0x1.425198a355fe0p-1,
    0x1.44f114a493676p-1, 0x1.479685fdf500fp-1, 0x1.4a42172dc5276p-1,
    0x1.4cf3f4f494ebep-1, 0x1.4fac4e820b665p-1, 0x1.526b55a656cd3p-1,
    0x1.55313f08d9e44p-1, 0x1.57fe4264c8d8cp-1, 0x1.5ad29acc85c85p-1,
    0x1.5dae86f4aff66p-1, 0x1.6092498802661p-1, 0x1.637e298550c15p-1,
    0x1.667272a92e320p-1, 0x1.696f75e513b26p-1, 0x1.6c7589e635a86p-1,
    0x1.6f850baea7aebp-1, 0x1.729e5f43f6d0ep-1, 0x1.75c1f0770d852p-1,
    0x1.78f033ca0b0d2p-1, 0x1.7c29a779c6855p-1, 0x1.7f6ed4b20e2c8p-1,
    0x1.82c050f56cf6bp-1, 0x1.861ebfc37bca8p-1, 0x1.898ad48badefep-1,
    0x1.8d0554fe60aa4p-1, 0x1.908f1bd31714bp-1, 0x1.94291c21b7a43p-1,
    0x1.97d4657617abep-1, 0x1.9b9228d24067ep-1, 0x1.9f63bee651fd5p-1,
    0x1.a34aafdf5af0cp-1, 0x1.a748bd550c9dep-1, 0x1.ab5fef17a2502p-1,
    0x1.af92a3f6ce8a0p-1, 0x1.b3e3a8234dd0ep-1, 0x1.b85653a8ff54fp-1,
    0x1.bceeb4ee1dc7fp-1, 0x1.c1b1cd9eebae7p-1, 0x1.c6a5ecea9787cp-1,
    0x1.cbd33a8a72de8p-1, 0x1.d144978a119d9p-1, 0x1.d70920657bcefp-1,
    0x1.dd36fa704de92p-1, 0x1.e3f11e027f074p-1, 0x1.eb7545b6ca912p-1,
    0x1.f446ac979f084p-1, 0x1.0000000000000p+0,
};

/* The slow path reads its further draws from r directly (q = NULL) or through the queue q. */
static inline uint64_t s_next(vafm_rngq *q, vafm_rng *r)
{
    return q ? vafm_rngq_u64(q, r) : vafm_rng_u64_inline(r);
}

/* Uniform in (0, 1], for the logarithms of the tail. */
static inline double s_open01(vafm_rngq *q, vafm_rng *r)
{
    return (double)((s_next(q, r) >> 11) + 1u) * 0x1.0p-53;
}

static inline double s_normal_slow(vafm_rngq *q, vafm_rng *r, uint64_t u)
{
    for (;;) {
        const unsigned i = (unsigned)(u & 0xffu);
        const uint64_t j = u >> 11;
        const int neg = (int)((u >> 8) & 1u);
        double x = (double)j * vafm_zig_w[i];
        if (j < vafm_zig_k[i])
            return neg ? -x : x; /* fast accept (a redraw after a rejection) */
        if (i == 0) {
            /* Tail x > r (Marsaglia 1964): x = r + e1 / r, accept if 2 e2 > (e1 / r)^2, e1, e2 ~ Exp(1). */
            double t, e;
            do {
                t = -log(s_open01(q, r)) * ZIG_INV_R;
                e = -log(s_open01(q, r));
            } while (e + e < t * t);
            x = ZIG_R + t;
            return neg ? -x : x;
        }
        /* Wedge of layer i, X[i+1] <= x < X[i]: a uniform height in [F[i], F[i+1]) under the curve. */
        const double y = vafm_zig_f[i] + (double)(s_next(q, r) >> 11) * 0x1.0p-53 * (vafm_zig_f[i + 1] - vafm_zig_f[i]);
        if (y < exp(-0.5 * x * x))
            return neg ? -x : x;
        u = s_next(q, r);
    }
}

VAFM_RNG_HIDDEN VAFM_RNG_COLD double vafm_rng_normal_slow(vafm_rng *r, uint64_t u)
{
    return s_normal_slow(NULL, r, u);
}

VAFM_RNG_HIDDEN VAFM_RNG_COLD double vafm_rngq_normal_slow(vafm_rngq *q, vafm_rng *r, uint64_t u)
{
    return s_normal_slow(q, r, u);
}

/* ---- blocks ahead ---------------------------------------------------------------------------- */

/* The ten rounds on two vectors of blocks per word (a, b), each 64-bit lane one block's word in its low half
 * (the multiplies read only the low halves; the high halves carry junk that no later step reads). V is the
 * vector type, the others the instruction set's set1, 32x32->64 multiply, right shift and XOR. The same
 * rounds as s_philox4x32_10. */
#define S_PHILOX_ROUNDS(V, set1, mul, srl, xor_)                                                      \
    do {                                                                                              \
        for (int round = 0; round < 10; round++) {                                                    \
            const V kk0 = set1(k0), kk1 = set1(k1);                                                   \
            const V p0a = mul(m0, c0a), p0b = mul(m0, c0b);                                           \
            const V p1a = mul(m1, c2a), p1b = mul(m1, c2b);                                           \
            c0a = xor_(xor_(srl(p1a, 32), c1a), kk0);                                                 \
            c0b = xor_(xor_(srl(p1b, 32), c1b), kk0);                                                 \
            c2a = xor_(xor_(srl(p0a, 32), c3a), kk1);                                                 \
            c2b = xor_(xor_(srl(p0b, 32), c3b), kk1);                                                 \
            c1a = p1a;                                                                                \
            c1b = p1b;                                                                                \
            c3a = p0a;                                                                                \
            c3b = p0b;                                                                                \
            k0 += VAFM_PHILOX_W0;                                                                     \
            k1 += VAFM_PHILOX_W1;                                                                     \
        }                                                                                             \
    } while (0)

#if defined(__SSE2__)
#include <emmintrin.h>

/* Four blocks side by side, two per vector: each 64-bit lane holds one block's 32-bit word in its low
 * half (pmuludq multiplies the low halves; the high halves carry junk that no later step reads). */
static void s_blocks4(const uint32_t ctr[4], const uint32_t key[2], uint32_t *out)
{
    const uint64_t base = (uint64_t)ctr[0] | (uint64_t)ctr[1] << 32;
    const uint64_t b0 = base, b1 = base + 1, b2 = base + 2, b3 = base + 3;
    __m128i c0a = _mm_set_epi64x((long long)(b1 & 0xffffffffu), (long long)(b0 & 0xffffffffu));
    __m128i c0b = _mm_set_epi64x((long long)(b3 & 0xffffffffu), (long long)(b2 & 0xffffffffu));
    __m128i c1a = _mm_set_epi64x((long long)(b1 >> 32), (long long)(b0 >> 32));
    __m128i c1b = _mm_set_epi64x((long long)(b3 >> 32), (long long)(b2 >> 32));
    __m128i c2a = _mm_set1_epi64x(ctr[2]), c2b = c2a;
    __m128i c3a = _mm_set1_epi64x(ctr[3]), c3b = c3a;
    const __m128i m0 = _mm_set1_epi64x(VAFM_PHILOX_M0), m1 = _mm_set1_epi64x(VAFM_PHILOX_M1);
    uint32_t k0 = key[0], k1 = key[1];
    S_PHILOX_ROUNDS(__m128i, _mm_set1_epi64x, _mm_mul_epu32, _mm_srli_epi64, _mm_xor_si128);
    /* low halves to words: x01 = c0, c1 of both blocks, x23 = c2, c3; then block by block */
    const __m128i x01a = _mm_unpacklo_epi32(_mm_shuffle_epi32(c0a, 0x08), _mm_shuffle_epi32(c1a, 0x08));
    const __m128i x23a = _mm_unpacklo_epi32(_mm_shuffle_epi32(c2a, 0x08), _mm_shuffle_epi32(c3a, 0x08));
    const __m128i x01b = _mm_unpacklo_epi32(_mm_shuffle_epi32(c0b, 0x08), _mm_shuffle_epi32(c1b, 0x08));
    const __m128i x23b = _mm_unpacklo_epi32(_mm_shuffle_epi32(c2b, 0x08), _mm_shuffle_epi32(c3b, 0x08));
    _mm_storeu_si128((__m128i *)(void *)(out + 0), _mm_unpacklo_epi64(x01a, x23a));
    _mm_storeu_si128((__m128i *)(void *)(out + 4), _mm_unpackhi_epi64(x01a, x23a));
    _mm_storeu_si128((__m128i *)(void *)(out + 8), _mm_unpacklo_epi64(x01b, x23b));
    _mm_storeu_si128((__m128i *)(void *)(out + 12), _mm_unpackhi_epi64(x01b, x23b));
}

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#include <immintrin.h>
#define S_HAVE_AVX2_BLOCKS 1

/* Eight blocks, four per vector, on CPUs with AVX2 (chosen at run time; the same words). */
__attribute__((target("avx2"))) static void s_blocks8_avx2(const uint32_t ctr[4], const uint32_t key[2], uint32_t *out)
{
    const uint64_t base = (uint64_t)ctr[0] | (uint64_t)ctr[1] << 32;
    uint64_t lo[8], hi[8];
    for (unsigned j = 0; j < 8; j++) {
        lo[j] = (base + j) & 0xffffffffu;
        hi[j] = (base + j) >> 32;
    }
    /* lanes: a = blocks 0, 1 | 4, 5 and b = 2, 3 | 6, 7, so that the in-lane transpose below puts
     * blocks 0-3 in the low 128-bit halves and 4-7 in the high ones */
    __m256i c0a = _mm256_set_epi64x((long long)lo[5], (long long)lo[4], (long long)lo[1], (long long)lo[0]);
    __m256i c0b = _mm256_set_epi64x((long long)lo[7], (long long)lo[6], (long long)lo[3], (long long)lo[2]);
    __m256i c1a = _mm256_set_epi64x((long long)hi[5], (long long)hi[4], (long long)hi[1], (long long)hi[0]);
    __m256i c1b = _mm256_set_epi64x((long long)hi[7], (long long)hi[6], (long long)hi[3], (long long)hi[2]);
    __m256i c2a = _mm256_set1_epi64x(ctr[2]), c2b = c2a;
    __m256i c3a = _mm256_set1_epi64x(ctr[3]), c3b = c3a;
    const __m256i m0 = _mm256_set1_epi64x(VAFM_PHILOX_M0), m1 = _mm256_set1_epi64x(VAFM_PHILOX_M1);
    uint32_t k0 = key[0], k1 = key[1];
    S_PHILOX_ROUNDS(__m256i, _mm256_set1_epi64x, _mm256_mul_epu32, _mm256_srli_epi64, _mm256_xor_si256);
    /* per 128-bit half as in s_blocks4: lo64 = the half's first block, hi64 = its second */
    const __m256i x01a = _mm256_unpacklo_epi32(_mm256_shuffle_epi32(c0a, 0x08), _mm256_shuffle_epi32(c1a, 0x08));
    const __m256i x23a = _mm256_unpacklo_epi32(_mm256_shuffle_epi32(c2a, 0x08), _mm256_shuffle_epi32(c3a, 0x08));
    const __m256i x01b = _mm256_unpacklo_epi32(_mm256_shuffle_epi32(c0b, 0x08), _mm256_shuffle_epi32(c1b, 0x08));
    const __m256i x23b = _mm256_unpacklo_epi32(_mm256_shuffle_epi32(c2b, 0x08), _mm256_shuffle_epi32(c3b, 0x08));
    const __m256i la = _mm256_unpacklo_epi64(x01a, x23a), ha = _mm256_unpackhi_epi64(x01a, x23a); /* 0 | 4, 1 | 5 */
    const __m256i lb = _mm256_unpacklo_epi64(x01b, x23b), hb = _mm256_unpackhi_epi64(x01b, x23b); /* 2 | 6, 3 | 7 */
    _mm256_storeu_si256((__m256i *)(void *)(out + 0), _mm256_permute2x128_si256(la, ha, 0x20));  /* 0, 1 */
    _mm256_storeu_si256((__m256i *)(void *)(out + 8), _mm256_permute2x128_si256(lb, hb, 0x20));  /* 2, 3 */
    _mm256_storeu_si256((__m256i *)(void *)(out + 16), _mm256_permute2x128_si256(la, ha, 0x31)); /* 4, 5 */
    _mm256_storeu_si256((__m256i *)(void *)(out + 24), _mm256_permute2x128_si256(lb, hb, 0x31)); /* 6, 7 */
}

/* Sixteen blocks, eight per vector, on CPUs with AVX-512F (chosen at run time; the same words). Each
 * 64-bit lane holds one block's 32-bit word in its low half, as in s_blocks4. */
__attribute__((target("avx512f"))) static void s_blocks16_avx512(const uint32_t ctr[4], const uint32_t key[2],
                                                                  uint32_t *out)
{
    const uint64_t base = (uint64_t)ctr[0] | (uint64_t)ctr[1] << 32;
    const __m512i ba = _mm512_add_epi64(_mm512_set1_epi64((long long)base), _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0));
    const __m512i bb = _mm512_add_epi64(ba, _mm512_set1_epi64(8));
    const __m512i lo32 = _mm512_set1_epi64(0xffffffffLL);
    __m512i c0a = ba, c0b = bb; /* the high halves are never read */
    __m512i c1a = _mm512_srli_epi64(ba, 32), c1b = _mm512_srli_epi64(bb, 32);
    __m512i c2a = _mm512_set1_epi64(ctr[2]), c2b = c2a;
    __m512i c3a = _mm512_set1_epi64(ctr[3]), c3b = c3a;
    const __m512i m0 = _mm512_set1_epi64(VAFM_PHILOX_M0), m1 = _mm512_set1_epi64(VAFM_PHILOX_M1);
    uint32_t k0 = key[0], k1 = key[1];
    S_PHILOX_ROUNDS(__m512i, _mm512_set1_epi64, _mm512_mul_epu32, _mm512_srli_epi64, _mm512_xor_si512);
    /* words 0|1 and 2|3 of each block in one 64-bit lane, then the blocks' 128 bits in order */
    const __m512i x01a = _mm512_or_si512(_mm512_and_si512(c0a, lo32), _mm512_slli_epi64(c1a, 32));
    const __m512i x23a = _mm512_or_si512(_mm512_and_si512(c2a, lo32), _mm512_slli_epi64(c3a, 32));
    const __m512i x01b = _mm512_or_si512(_mm512_and_si512(c0b, lo32), _mm512_slli_epi64(c1b, 32));
    const __m512i x23b = _mm512_or_si512(_mm512_and_si512(c2b, lo32), _mm512_slli_epi64(c3b, 32));
    const __m512i ea = _mm512_unpacklo_epi64(x01a, x23a), oa = _mm512_unpackhi_epi64(x01a, x23a); /* 0 2 4 6 | 1 3 5 7 */
    const __m512i eb = _mm512_unpacklo_epi64(x01b, x23b), ob = _mm512_unpackhi_epi64(x01b, x23b);
    const __m512i i0 = _mm512_set_epi64(11, 10, 3, 2, 9, 8, 1, 0), i1 = _mm512_set_epi64(15, 14, 7, 6, 13, 12, 5, 4);
    _mm512_storeu_si512((void *)(out + 0), _mm512_permutex2var_epi64(ea, i0, oa));
    _mm512_storeu_si512((void *)(out + 16), _mm512_permutex2var_epi64(ea, i1, oa));
    _mm512_storeu_si512((void *)(out + 32), _mm512_permutex2var_epi64(eb, i0, ob));
    _mm512_storeu_si512((void *)(out + 48), _mm512_permutex2var_epi64(eb, i1, ob));
}
#endif
#else
static void s_blocks4(const uint32_t ctr[4], const uint32_t key[2], uint32_t *out)
{
    const uint64_t base = (uint64_t)ctr[0] | (uint64_t)ctr[1] << 32;
    for (unsigned j = 0; j < 4; j++) {
        const uint64_t b = base + j;
        const uint32_t c[4] = { (uint32_t)b, (uint32_t)(b >> 32), ctr[2], ctr[3] };
        s_philox4x32_10(c, key, out + 4 * j);
    }
}
#endif

/* Advance a counter's low 64 bits (c[0] | c[1] << 32) by n blocks. */
static void s_ctr_add(uint32_t c[4], unsigned n)
{
    const uint64_t b = ((uint64_t)c[0] | (uint64_t)c[1] << 32) + n;
    c[0] = (uint32_t)b;
    c[1] = (uint32_t)(b >> 32);
}

VAFM_RNG_HIDDEN void vafm_philox4x32_10_blocks(const uint32_t ctr[4], const uint32_t key[2], unsigned nb, uint32_t *out)
{
    uint32_t c[4] = { ctr[0], ctr[1], ctr[2], ctr[3] };
    unsigned j = 0;
#ifdef S_HAVE_AVX2_BLOCKS
    if (__builtin_cpu_supports("avx512f")) {
        for (; j + 16 <= nb; j += 16) {
            s_blocks16_avx512(c, key, out + 4 * j);
            s_ctr_add(c, 16);
        }
    }
    if (__builtin_cpu_supports("avx2")) {
        for (; j + 8 <= nb; j += 8) {
            s_blocks8_avx2(c, key, out + 4 * j);
            s_ctr_add(c, 8);
        }
    }
#endif
    for (; j < nb; j += 4) {
        s_blocks4(c, key, out + 4 * j);
        s_ctr_add(c, 4);
    }
}

/* Refill q from r: q's unread words moved to the front, then what is left of r's current block, then the next
 * VAFM_RNGQ_BLOCKS blocks of r's stream (r's counter advanced past them). The caller sets q->pos. */
static void s_rngq_refill(vafm_rngq *q, vafm_rng *r)
{
    unsigned k = 0;
    while (q->pos < q->len)
        q->w[k++] = q->w[q->pos++];
    while (r->pos < 4)
        q->w[k++] = r->buf[r->pos++];
    vafm_philox4x32_10_blocks(r->ctr, r->key, VAFM_RNGQ_BLOCKS, q->w + k);
    s_ctr_add(r->ctr, VAFM_RNGQ_BLOCKS);
    q->len = k + 4 * VAFM_RNGQ_BLOCKS;
}

VAFM_RNG_HIDDEN void vafm_rngq_top_up(vafm_rngq *q, vafm_rng *r)
{
    if (q->len - q->pos >= 16)
        return;
    s_rngq_refill(q, r);
    q->pos = 0;
}

VAFM_RNG_HIDDEN uint64_t vafm_rngq_u64_slow(vafm_rngq *q, vafm_rng *r)
{
    /* the unread words first (at most one: reads take two), then what is left of r's current block */
    s_rngq_refill(q, r);
    q->pos = 2;
    return (uint64_t)q->w[0] | (uint64_t)q->w[1] << 32;
}

VAFM_API void vafm_philox4x32_10(const uint32_t ctr[4], const uint32_t key[2], uint32_t out[4])
{
    s_philox4x32_10(ctr, key, out);
}

VAFM_API void vafm_rng_init(vafm_rng *r, uint64_t seed, uint64_t stream)
{
    r->key[0] = (uint32_t)seed;
    r->key[1] = (uint32_t)(seed >> 32);
    r->ctr[0] = 0;
    r->ctr[1] = 0;
    r->ctr[2] = (uint32_t)stream;
    r->ctr[3] = (uint32_t)(stream >> 32);
    for (int k = 0; k < 4; k++)
        r->buf[k] = 0;
    r->pos = 4;
}

VAFM_API uint32_t vafm_rng_u32(vafm_rng *r)
{
    return vafm_rng_u32_inline(r);
}

VAFM_API uint64_t vafm_rng_u64(vafm_rng *r)
{
    return vafm_rng_u64_inline(r);
}

VAFM_API double vafm_rng_uniform(vafm_rng *r)
{
    return vafm_rng_uniform_inline(r);
}

VAFM_API double vafm_rng_normal(vafm_rng *r)
{
    return vafm_rng_normal_inline(r);
}
