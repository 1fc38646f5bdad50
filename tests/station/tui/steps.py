"""Steps the TUI tests take the way a user does (through keys, fields and buttons)."""

from __future__ import annotations

from textual.widgets import Input


async def open_session(pilot, wait_until, mode_key: str, path) -> None:
    """Go to the page of `mode_key` (e.g. "f3" Results), type `path` into its session picker and
    press Open. `wait_until` is the conftest fixture's bounded wait."""
    app = pilot.app
    await pilot.press(mode_key)
    await wait_until(pilot, lambda: app.screen.query("#session-path"), what="the session picker")
    app.screen.query_one("#session-path", Input).value = str(path)
    await pilot.click("#session-open")


async def connect_and_fit(pilot, wait_until, connected, path) -> None:
    """Wait for the rig, open `path` on Results (F3) and wait for its fit: the model the
    Compensation page makes its table from."""
    await connected(pilot)
    await open_session(pilot, wait_until, "f3", path)
    await wait_until(pilot, lambda: pilot.app.analysis is not None, 60, "the fit")


async def type_keys(pilot, text: str) -> None:
    """Type `text` key by key as Pilot.press does (each character a Key event sent through the
    app's driver, the way a terminal sends them), without waiting for the app to go idle between
    keys: a typist's burst (Pilot.press waits after each key, so on a busy machine its keys can be
    a second apart). Then wait until the app has handled them all."""
    from textual import events
    from textual.app import _character_to_key  # the key names Pilot.press gives characters

    app = pilot.app
    for char in text:
        key = _character_to_key(char) if not char.isalnum() else char
        event = events.Key(key, char)
        event.set_sender(app)
        app._driver.send_message(event)
    await pilot.pause()


async def press_to_quit(pilot, key: str, timeout_s: float = 30.0) -> None:
    """Press `key`, which ends the app (ctrl+q with nothing running, or the yes of the quit
    dialog), and wait until the app has ended. The key goes through the app's driver as
    Pilot.press sends it, but without Pilot.press's wait for the screen's widgets to handle a
    callback each: under load Pilot's idle check returns before the key is handled, that wait
    then begins on widgets that close with the app and never run it (WaitForScreenTimeout after
    30 s). The wait here polls the app, not its widgets."""
    import asyncio
    import time

    from textual import events

    app = pilot.app
    event = events.Key(key, key if len(key) == 1 else None)
    event.set_sender(app)
    app._driver.send_message(event)
    deadline = time.monotonic() + timeout_s
    while app.is_running:
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {key} to end the app")
        await asyncio.sleep(0.01)


async def choose_plan(pilot, plan: str, timeout_s: float = 30.0) -> None:
    """Choose `plan` on the Sweep page and wait until the page has answered: choosing a plan fills
    a cycles field left blank or at a plan's standard number with the plan's own (ISO 230-2: 5,
    the paper: 6), and an answer that comes after the next field is typed would overwrite a 5 or a
    6 typed there. The cycles field is blanked first so the answer is seen; a number typed before
    (not a standard one) is put back, as the page keeps it."""
    import asyncio
    import time

    from textual.widgets import Select

    from procedures.acquisition.plan_spec import DEFAULT_CYCLES

    screen = pilot.app.screen
    select = screen.query_one("#plan", Select)
    if select.value == plan:
        return  # no change, no answer to wait for
    cycles = screen.query_one("#cycles", Input)
    before = cycles.value
    cycles.value = ""
    select.value = plan
    deadline = time.monotonic() + timeout_s
    while cycles.value != str(DEFAULT_CYCLES[plan]):
        if time.monotonic() > deadline:
            raise AssertionError(f"the Sweep page did not answer the choice of plan {plan!r} in {timeout_s:g} s")
        await asyncio.sleep(0.01)
    if before.strip() not in ("", *(str(n) for n in DEFAULT_CYCLES.values())):
        cycles.value = before
    await pilot.pause()
