// A facepuppet control box in a few lines: buttons on pins 2-5 (to ground, internal pull-ups),
// a potentiometer on A0, a rotary encoder on pins 6/7, a LED on pin 13 lit by the host (L0 1).
// Protocol (docs/devices.md): "B<n> 0|1", "D<n> +/-counts", "A<n> 0.000-1.000", one per line.
// Open it with:  puppet monitor "serial:///dev/ttyACM0?baud=115200"

const int buttonPins[] = {2, 3, 4, 5};
int lastButton[4];
int lastAxis = -1;
int lastA = HIGH;

void setup() {
  Serial.begin(115200);
  for (int i = 0; i < 4; i++) { pinMode(buttonPins[i], INPUT_PULLUP); lastButton[i] = HIGH; }
  pinMode(6, INPUT_PULLUP); pinMode(7, INPUT_PULLUP); pinMode(13, OUTPUT);
  Serial.println("H arduino-textbox 4 buttons, 1 axis, 1 dial");
}

void loop() {
  for (int i = 0; i < 4; i++) {                       // buttons: report changes only
    int b = digitalRead(buttonPins[i]);
    if (b != lastButton[i]) { lastButton[i] = b; Serial.print("B"); Serial.print(i); Serial.println(b == LOW ? " 1" : " 0"); }
  }
  int a = analogRead(A0);                              // axis: report when it moves
  if (abs(a - lastAxis) > 2) { lastAxis = a; Serial.print("A0 "); Serial.println(a / 1023.0, 3); }
  int enc = digitalRead(6);                            // encoder: one count per edge of A
  if (enc != lastA) { lastA = enc; if (enc == LOW) Serial.println(digitalRead(7) == HIGH ? "D0 +1" : "D0 -1"); }
  if (Serial.available()) {                            // lights: "L0 1" / "L0 0"
    String cmd = Serial.readStringUntil('\n');
    if (cmd.startsWith("L0 ")) digitalWrite(13, cmd.endsWith("1") ? HIGH : LOW);
  }
  delay(1);
}
