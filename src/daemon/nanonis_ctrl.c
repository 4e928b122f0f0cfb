/* SPDX-License-Identifier: MIT */
/*
 * Nanonis ZCtrl, Motor, AutoApproach and FolMe: the always-on controller's commands in Nanonis words
 * (nanonis_cmds.h; docs/nanonis.md).
 */
#include <stdio.h>
#include "daemon/nanonis_cmds.h"

static int h_not_yet(nnc_ctx *x)
{
    int rc = nnc_ping(x);
    if (rc)
        return rc;
    snprintf(x->err, sizeof x->err, "%s: not yet: needs the always-on controller (vafm issue #26)",
             nn_conn_cmd(x->c));
    return NNC_FAIL;
}

const nnc_cmd nnc_ctrl_cmds[] = {
    { "ZCtrl.OnOffSet", h_not_yet, "" },
    { "ZCtrl.OnOffGet", h_not_yet, "I" },
    { "ZCtrl.ZPosSet", h_not_yet, "" },
    { "ZCtrl.ZPosGet", h_not_yet, "f" },
    { "ZCtrl.SetpntSet", h_not_yet, "" },
    { "ZCtrl.SetpntGet", h_not_yet, "f" },
    { "ZCtrl.GainSet", h_not_yet, "" },
    { "ZCtrl.GainGet", h_not_yet, "fff" },
    { "ZCtrl.Withdraw", h_not_yet, "" },
    { "ZCtrl.LimitsSet", h_not_yet, "" },
    { "ZCtrl.LimitsGet", h_not_yet, "ff" },
    { "ZCtrl.StatusGet", h_not_yet, "H" },
    { "ZCtrl.TipLiftSet", h_not_yet, "" },
    { "ZCtrl.TipLiftGet", h_not_yet, "f" },
    { "ZCtrl.Home", h_not_yet, "" },
    { "ZCtrl.HomePropsSet", h_not_yet, "" },
    { "ZCtrl.HomePropsGet", h_not_yet, "Hf" },
    { "ZCtrl.SwitchOffDelaySet", h_not_yet, "" },
    { "ZCtrl.SwitchOffDelayGet", h_not_yet, "f" },
    { "Motor.StartMove", h_not_yet, "" },
    { "Motor.StartClosedLoop", h_not_yet, "" },
    { "Motor.StopMove", h_not_yet, "" },
    { "Motor.PosGet", h_not_yet, "ddd" },
    { "Motor.StepCounterGet", h_not_yet, "iii" },
    { "Motor.FreqAmpGet", h_not_yet, "ff" },
    { "Motor.FreqAmpSet", h_not_yet, "" },
    { "AutoApproach.Open", h_not_yet, "" },
    { "AutoApproach.OnOffSet", h_not_yet, "" },
    { "AutoApproach.OnOffGet", h_not_yet, "H" },
    { "FolMe.XYPosSet", h_not_yet, "" },
    { "FolMe.XYPosGet", h_not_yet, "dd" },
    { "FolMe.SpeedSet", h_not_yet, "" },
    { "FolMe.SpeedGet", h_not_yet, "fI" },
    { "FolMe.Stop", h_not_yet, "" },
};
const size_t nnc_ctrl_ncmds = sizeof nnc_ctrl_cmds / sizeof nnc_ctrl_cmds[0];
