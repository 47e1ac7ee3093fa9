// A viewer on the Foxglove WebSocket protocol's own client library (@foxglove/ws-protocol)
// that publishes COUNT messages on a channel of its own it never advertised, as soon as the
// server has introduced itself, then subscribes to every channel it is told of and prints
// what it receives as JSON lines (as foxglove_client.js does) until the first message has
// come (the server read everything before the subscription) or SECONDS have passed.
//   node foxglove_publisher.js URL COUNT SECONDS
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, count, seconds] = process.argv.slice(2);
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map();
let done = false;
const print = (line) => done || process.stdout.write(JSON.stringify(line) + "\n");
const finish = () => {
  done = true;
  process.stdout.write("", () => process.exit(0));
};

client.on("serverInfo", (info) => {
  print({ serverInfo: info });
  const payload = new TextEncoder().encode(JSON.stringify({ data: "not for the robot" }));
  for (let i = 0; i < Number(count); i++) {
    client.sendMessage(7 + (i % 3), payload); // channels 7, 8 and 9: never advertised
  }
  print({ sent: Number(count) });
});
client.on("advertise", (advertised) => {
  print({ advertise: advertised });
  for (const channel of advertised) {
    channels.set(client.subscribe(channel.id), channel.id);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const bytes = Buffer.from(data.buffer, data.byteOffset, data.byteLength);
  print({ message: { channelId: channels.get(subscriptionId), logTime: String(timestamp),
                     data: bytes.toString("base64") } });
  client.close();
  finish();
});
client.on("error", (error) => print({ error: String(error) }));
client.on("close", (event) => {
  print({ close: event.code });
  finish();
});
setTimeout(() => {
  client.close();
  finish();
}, Number(seconds) * 1000);
