"""Every reset of the EyeQ is counted in every summary, split by cause: asked by the host (its
EEPROM-driven reset, a reset after a failed boot) or not (the EyeQ reset by itself)."""

from __future__ import annotations

from eyeq_spi.emulator import build, summary
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.summary import SimSessions, format_summary, sim_summary


def test_the_reset_after_reading_the_eeprom_is_counted_as_asked() -> None:
    emu = build()  # an empty NVM: Fatal_Error 22, the EEPROM read, the EyeQ reset
    emu.run_for(2.0)
    assert any("resetting the EyeQ" in t.detail for t in emu.host.transitions)
    out = summary(emu)
    assert out["ok"], out["problem"]
    assert out["eyeq_resets"] == 1
    assert out["eyeq_reset_causes"] == {"asked_by_host": 1, "not_asked": 0}
    assert "EyeQ resets 1: asked by the host 1, not asked 0" in format_summary(out)


def test_a_reset_of_its_own_is_not_asked() -> None:
    emu = build(sim_config=SimConfig(reset_at=1.5))
    emu.run_for(3.0)
    out = summary(emu)
    causes = out["eyeq_reset_causes"]
    assert causes["not_asked"] == 1 and causes["asked_by_host"] >= 1, causes
    assert out["eyeq_resets"] == causes["not_asked"] + causes["asked_by_host"]


def test_the_sim_counts_a_soft_reset_as_asked() -> None:
    """The EyeQ's side of the host's soft reset (Switch EyeQ Application to Vision, L10)."""
    emu = build()
    served = SimSessions()
    served.begin(emu.sim)
    emu.run_for(2.0)
    served.add(emu.sim, began=0.0, ended=2.0, link_lost=None)
    out = sim_summary(emu.sim, served.sessions, elapsed=2.0, wall=2.0, cpu=0.0)
    causes = out["sessions"][0]["eyeq_reset_causes"]
    assert causes["not_asked"] == 0 and causes["asked_by_host"] >= 1, causes
    assert out["eyeq_reset_causes"] == causes
