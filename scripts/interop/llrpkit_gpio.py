#!/usr/bin/env python3
"""A GPI-gated conveyor application on llrpkit 0.3.0's library, unmodified.

What a line application does on a reader wired to a photo-eye: turn on GPIEvent and
ROSpecEvent notifications, then llrpkit's `Reader.inventory(gpi_trigger=PORT)`, which adds a
ROSpec that the reader itself starts when GPI PORT goes high and stops when it goes low
(GPITriggerValue start and GPI-with-timeout stop triggers), enables the port
(GPIPortCurrentState) and enables the ROSpec without starting it. Alongside, its
`gpi_events()` feed. Prints one JSON line per thing that happens, flushed at once:

  {"armed": true}                          the ROSpec is enabled and waits for the line
  {"gpi": PORT, "high": true|false}        a GPIEvent
  {"tag": "EPC hex"}                       a tag report
  {"error": "..."}                         something failed

and runs until its standard input closes (or --seconds pass), then stops and deletes the
ROSpec and disconnects.

Usage: llrpkit_gpio.py HOST PORT [--gpi 1] [--seconds 60]
"""
import argparse
import asyncio
import json
import sys

from llrpkit import Reader
from llrpkit.protocol import enums, messages, params


def say(**fields):
    print(json.dumps(fields), flush=True)


async def enable_events(reader):
    """GPIEvent and ROSpecEvent notifications on (a reader's factory state has them off)."""
    states = [
        params.EventNotificationState(event_type=int(t), notification_state=True)
        for t in (enums.NotificationEventType.GPI_Event, enums.NotificationEventType.ROSpec_Event)
    ]
    response = await reader.client.transact(
        messages.SET_READER_CONFIG(
            reader_event_notification_spec=params.ReaderEventNotificationSpec(
                event_notification_states=states
            )
        )
    )
    status = response.llrp_status.status_code
    if int(status) != 0:
        raise RuntimeError(f"SET_READER_CONFIG refused: {status}")


async def armed(reader):
    """Waits until the inventory's ROSpec is enabled and waiting (Inactive)."""
    while True:
        response = await reader.client.transact(messages.GET_ROSPECS())
        if any(int(s.current_state) == int(enums.ROSpecState.Inactive) for s in response.ro_specs):
            return
        await asyncio.sleep(0.05)


async def stdin_closed():
    loop = asyncio.get_running_loop()
    await loop.run_in_executor(None, sys.stdin.read)


async def run(host, port, gpi, seconds):
    async with Reader(host, port=port) as reader:
        await enable_events(reader)

        async def tags():
            async for tag in reader.inventory(gpi_trigger=gpi, gpi_active_high=True):
                say(tag=tag.epc_hex)

        async def edges():
            async for edge in reader.gpi_events():
                say(gpi=edge.port, high=edge.high)

        tasks = [asyncio.create_task(tags()), asyncio.create_task(edges())]
        await asyncio.wait_for(armed(reader), timeout=10)
        say(armed=True)
        try:
            await asyncio.wait_for(stdin_closed(), timeout=seconds)
        except TimeoutError:
            pass
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("host")
    ap.add_argument("port", type=int)
    ap.add_argument("--gpi", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args()
    try:
        asyncio.run(run(a.host, a.port, a.gpi, a.seconds))
    except Exception as e:  # reported, not raised: the test reads stdout
        say(error=f"{type(e).__name__}: {e}")
        sys.exit(1)


if __name__ == "__main__":
    main()
